"""``python -m quad_envs``: the quad-sindy command line."""

from quad_envs.cli import main

main()
