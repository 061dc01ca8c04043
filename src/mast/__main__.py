"""``python -m mast`` runs the command line."""

from .cli import main

main()
