"""offroad-path: learning off-road path prediction from stereo visual odometry labels.

Stages, each a Hydra app (`python -m offroad_path.<stage>`) and a DVC stage:
synthesize -> label -> split -> pretrain -> train -> postprocess -> evaluate.
"""

__version__ = "0.1.0"
