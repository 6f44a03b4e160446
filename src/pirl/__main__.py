"""``python -m pirl`` runs the command line."""

from pirl.cli import app

app(prog_name="pirl")
