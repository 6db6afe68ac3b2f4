"""``python -m quad_envs``: the quad-sindy command line."""

from quad_sindy.cli import main

main()
