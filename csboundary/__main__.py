"""``python -m csboundary`` runs the command line."""

from csboundary.cli.main import main

main()
