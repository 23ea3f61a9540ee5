"""AirPose reproducibility kit: the library behind the notebooks (see README.md)."""

__version__ = "0.1.0"
