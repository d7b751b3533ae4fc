"""``python -m dvrk_gym``: the ``dvrk-gym`` command (:func:`dvrk_gym.cli.main.main`)."""

from __future__ import annotations

import sys

from dvrk_gym.cli.main import main

if __name__ == "__main__":
    sys.exit(main())
