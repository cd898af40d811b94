"""Running a trained path model on new footage: frame sources, PyTorch and ONNX runners, export."""
