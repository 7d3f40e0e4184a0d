"""Per-track metrics and summary statistics."""
