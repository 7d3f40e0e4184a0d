"""Motion and measurement models shared by scenarios, estimators and metrics."""
