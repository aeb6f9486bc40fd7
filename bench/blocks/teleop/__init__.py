"""Suites of the teleop domain."""
