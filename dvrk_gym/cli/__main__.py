"""``python -m dvrk_gym.cli``: the same as the ``dvrk-gym`` command."""

import sys

from dvrk_gym.cli.main import main

sys.exit(main())
