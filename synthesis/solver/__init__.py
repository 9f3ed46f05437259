"""The conic solver layer (on the shipped path): cvxpy/Clarabel problems to a solution
(:mod:`~pressor.synthesis.solver.conic`), the Clarabel KKT fallback chain (:mod:`~pressor.synthesis.solver.kkt`)
and the single-thread BLAS pin of the synthesis process (:mod:`~pressor.synthesis.solver.blas_threads`).
"""
