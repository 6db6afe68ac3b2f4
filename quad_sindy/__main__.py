"""``python -m quad_sindy``: the quad-sindy command line."""

from quad_sindy.cli import main

main()
