"""Developer tools: benchmarks and evaluations run with ``python -m tools.<name>`` (make bench, make eval)."""
