"""One module per `cosim` sub-command; each defines `register(subparsers)`."""
