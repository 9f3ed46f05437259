"""The controller families: the name registry (:mod:`pressor.synthesis.families.registry`) and one
subpackage per family. ``smith`` is the shipped family; ``theorem3`` is the alternative (the
paper's Theorem-3 synthesis LMIs). The registry loads a family's module on first lookup only.
"""
