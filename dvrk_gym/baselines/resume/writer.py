"""Write a training's state every so many env steps, between episodes (a stable-baselines3 callback)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback

from dvrk_gym.baselines.resume.state_file import save_training_state
from dvrk_gym.utils.source_fingerprint import source_fingerprint


class TrainingStateWriter(BaseCallback):
    """Save the training state (:func:`~dvrk_gym.baselines.resume.state_file.save_training_state`)
    at each multiple of ``every`` env steps, or at the first moment after it when every
    training env is between episodes (multiples passed while waiting make one save).

    It saves as a rollout begins: the last step's transition is in the replay buffer and
    its gradient updates are done, so the file holds a consistent moment.

    Args:
        path: the state file.
        every: env steps between saves.
        config: the training settings, JSON values.
        progress: gives the training loop's own record to save with it, JSON values.
    """

    def __init__(self, path: str | Path, every: int, config: dict[str, Any], progress: Callable[[], dict[str, Any]]) -> None:
        super().__init__()
        if isinstance(every, bool) or not isinstance(every, int) or every < 1:
            raise ValueError(f"every must be an int >= 1 (env steps between saves), got {every!r}")
        try:
            json.dumps(config, allow_nan=False)
        except (TypeError, ValueError) as error:
            raise ValueError(f"the training settings must be JSON values to be saved with its state ({error})") from None
        source_fingerprint()  # stamp the code that runs this training now, before its files can be edited (cached per process)
        self.path = Path(path)
        self.every = every
        self.config = config
        self.progress = progress
        self.saves = 0
        self._due = every

    def _on_training_start(self) -> None:
        self._due = (self.num_timesteps // self.every + 1) * self.every  # a resumed run saves at the same steps

    def _on_rollout_start(self) -> None:
        if self.num_timesteps >= self._due and all(self.training_env.env_method("between_episodes")):
            save_training_state(self.path, self.model, self.config, self.progress())
            self.saves += 1
            self._due = (self.num_timesteps // self.every + 1) * self.every

    def _on_step(self) -> bool:
        return True
