"""Evaluation of any policy on the envs with fixed seeds (``episodes``) and the paper's debridement
trial table (``trials``); how the paper's table sent each calibrator's predictions
(``table_protocol``)."""
