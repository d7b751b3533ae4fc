"""Resume a killed training where its last saved state left it, bit for bit.

A training writes its whole state, without pickles, every so many env steps between
episodes (:class:`~dvrk_gym.baselines.resume.writer.TrainingStateWriter`): the model's
weights and optimisers, the replay buffer, the random generators, the learning curve so far,
and what each training env carries into its next reset
(:mod:`~dvrk_gym.baselines.resume.reset_records`). :func:`~dvrk_gym.baselines.resume.restore.restore_training_state`
puts it back into a model built afresh, and the training goes on as if it had never
stopped: the same final weights as a run never killed.
"""

from __future__ import annotations

from dvrk_gym.baselines.resume.reset_records import ResetRecorder
from dvrk_gym.baselines.resume.restore import restore_training_state
from dvrk_gym.baselines.resume.state_file import TrainingStateError, save_training_state
from dvrk_gym.baselines.resume.writer import TrainingStateWriter

STATE_FILE_NAME = "training_state.zip"
"""The file in a training's output folder that holds its state until its outputs are written
(``dvrk-gym baseline train``, and ``dvrk-gym reproduce``'s RL stage)."""

__all__ = ["STATE_FILE_NAME", "ResetRecorder", "TrainingStateError", "TrainingStateWriter", "restore_training_state", "save_training_state"]
