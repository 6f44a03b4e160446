"""``python -m pirl`` runs the command line."""

from pirl.cli import main

main()
