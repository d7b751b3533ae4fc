"""The simulated experiment, by concern: ``physics`` (PyBullet plumbing), ``robot`` (the arm and its cables),
``endoscope`` (cameras and perception), ``world`` (arm and endoscope in one physics client) and ``table``
(the debridement table beside the world). See ARCHITECTURE.md."""
