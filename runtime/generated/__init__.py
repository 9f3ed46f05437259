"""Generated controller modules committed for the runtime (written by ``pressor codegen``)."""
