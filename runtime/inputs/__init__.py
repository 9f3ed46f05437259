"""What a run is given: command-line configuration, clinician target and acknowledgements,
controller loading, syringe and drug library (``drug_library.toml`` is package data here).

On the shipped path: ``pressor run`` reads all of them before the loop starts (the target source
also during it).
"""
