"""The CNN fault classifier (issue 4): model, training, ONNX export, evaluation."""
