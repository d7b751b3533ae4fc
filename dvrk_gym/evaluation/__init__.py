"""Evaluation of any policy on the envs with fixed seeds (``episodes``) and the paper's debridement
trial table (``trials``)."""
