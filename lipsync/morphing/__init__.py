"""morphing room."""
