"""One module per ``loci`` command group; each has ``register(subparsers)``."""
