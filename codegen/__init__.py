"""Code generation: from a synthesis artifact to a standalone scheduled controller (Python, C99)."""
