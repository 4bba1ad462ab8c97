"""Data transcribed from the seed dissertation (tables only; no behaviour)."""
