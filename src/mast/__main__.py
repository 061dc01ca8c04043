"""``python -m mast`` runs the command line."""

from mast.apps.cli import main

main()
