"""The conic solver layer (on the shipped path): cvxpy/Clarabel problems to a solution
(:mod:`~synthesis.solver.conic`), the Clarabel KKT fallback chain (:mod:`~synthesis.solver.kkt`)
and the single-thread BLAS pin of the synthesis process (:mod:`~synthesis.solver.blas_threads`).
"""
