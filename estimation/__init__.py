"""estimation package (in progress)."""
