"""diagnosis package (in progress)."""
