"""In-silico cohort trials (``pressor trial``): seeded patients run in process, one controller or
several compared per patient (paired statistics), the §3 metrics, and the HTML report.
"""
