"""Prints the env benchmark (same as ``quad-sindy bench envs``): steps/s and Pendulum ratios."""

import sys

from quad_sindy.cli import main

if __name__ == "__main__":
    sys.argv = ["quad-sindy", "bench", "envs", *sys.argv[1:]]
    main()
