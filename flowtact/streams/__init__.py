"""Helpers a block uses to pair and join its input streams (by arrival order, by time)."""
