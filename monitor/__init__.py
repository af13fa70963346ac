"""propwatch onboard side: numpy, pymavlink and onnxruntime only (never torch or offline)."""

__version__ = "0.1.0"
