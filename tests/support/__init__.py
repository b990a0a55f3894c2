"""Helpers shared by tests of several layers (not tests themselves)."""
