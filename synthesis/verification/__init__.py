"""``pressor verify``'s independent checks of an artifact (on the shipped path): check (a) through the
family's certificate, frozen delay-system stability on a dense grid, and the nominal step against
the PI and Smith-predictor baselines; also the step-only check of a plugin controller.
"""
