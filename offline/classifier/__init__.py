"""The CNN fault classifier: model, training, ONNX export, evaluation."""
