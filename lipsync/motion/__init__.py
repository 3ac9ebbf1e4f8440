"""motion room."""
