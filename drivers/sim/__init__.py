"""Simulated twins of the drivers: virtual LMS, base and camera over a simulated world."""
