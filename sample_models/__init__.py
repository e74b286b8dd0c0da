"""Scripts that generate the sample scenes (each also runs as ``python sample_models/NAME.py``)."""
