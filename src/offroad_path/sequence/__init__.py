"""Stereo sequences on disk: the layout every stage reads and the synthetic world writes."""

from offroad_path.sequence.calibration import StereoCalibration
from offroad_path.sequence.reader import Sequence, find_sequences, open_sequence, sequence_names

__all__ = ["Sequence", "StereoCalibration", "find_sequences", "open_sequence", "sequence_names"]
