"""Reusable densities for importance sampling."""
