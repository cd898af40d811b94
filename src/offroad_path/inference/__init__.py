"""A trained path model on new images: PyTorch and ONNX runners (runners), the paper's post-processing
(path_filter) and the temporal filter (temporal_filter). Frame sources: offroad_path.predict; export:
offroad_path.export."""
