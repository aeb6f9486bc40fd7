"""Stands in for a heavy optional dependency (torch, OpenCV) in the lazy-import test."""
