"""Developer tools: benchmarks and evaluations run with ``python -m agent.tools.<name>`` (make bench, make eval)."""
