"""The places layer: scan features (book App. A, B), boosting, decision lists, place models."""
