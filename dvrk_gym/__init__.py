"""dvrk-gym: a simulated da Vinci Research Kit for calibration and debridement research."""

__version__ = "0.1.0"
