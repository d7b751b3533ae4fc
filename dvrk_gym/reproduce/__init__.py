"""``dvrk-gym reproduce``: the paper's experiment end to end in simulation, with a report.

>>> from dvrk_gym.reproduce import ReproduceConfig, run_reproduce, QUICK
>>> run = run_reproduce(ReproduceConfig(out="dvrk_gym_out/reproduce-quick", profile=QUICK))  # doctest: +SKIP
>>> run.report  # doctest: +SKIP
PosixPath('dvrk_gym_out/reproduce-quick/report.md')
"""

from dvrk_gym.reproduce.profiles import FULL, PROFILES, QUICK, TINY, Profile
from dvrk_gym.reproduce.run import ReproduceConfig, Reproduction, build_tasks, run_reproduce

__all__ = ["FULL", "PROFILES", "QUICK", "TINY", "Profile", "Reproduction", "ReproduceConfig", "build_tasks", "run_reproduce"]
