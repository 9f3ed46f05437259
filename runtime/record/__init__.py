"""What a run leaves behind while it runs: the rerun recording and its viewer layout.

On the shipped path only when ``pressor run --rrd`` asks for a recording (``pressor sil`` always).
"""
