"""propwatch export: checkpoint (.pt) -> ONNX file for the monitor, checked by loading it back."""

from __future__ import annotations

import argparse
from pathlib import Path

from monitor.model import Classifier


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="propwatch export", description=__doc__)
    p.add_argument("checkpoint", type=Path, help="checkpoint written by propwatch train (.pt)")
    p.add_argument("--out", type=Path, required=True, help="ONNX path")
    a = p.parse_args(argv)
    from offline.classifier.export import export_onnx  # torch: only once there is work to do
    from offline.classifier.train import load_checkpoint

    path = export_onnx(load_checkpoint(a.checkpoint), a.out)
    info = Classifier(path).info  # the monitor's own loader must accept it
    print(f"wrote {path}: {len(info.features)} features x {info.window} steps at {info.sample_rate_hz} Hz")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
