"""Scores of what the agent built against ground truth (real robot logs)."""
