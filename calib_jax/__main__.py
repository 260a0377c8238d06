"""``python -m calib_jax ARGS``: the same front door as the ``calib-jax`` console script."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
