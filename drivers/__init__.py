"""Device drivers: bytes from hardware to typed messages and back, each with a simulated twin."""
