"""``python -m mast`` runs the command line."""

from mast.program import main

main()
