"""Entry point of the PyInstaller bundle: the same ``main`` as the ``stylize3d`` console script.

``STYLIZE3D_BUNDLE_CHECK=1 stylize3d`` prints, as JSON, where the frozen app finds its resources
(used by packaging/smoke_test.py) and exits.
"""

import os
import sys


def _bundle_check() -> int:
    import json
    from pathlib import Path

    from algorithms.mesh.samples import SAMPLES_DIR, available_samples
    from app.panels.analogies import STYLE_DIR

    res = SAMPLES_DIR.parent
    print(json.dumps({
        "frozen": bool(getattr(sys, "frozen", False)),
        "meipass": getattr(sys, "_MEIPASS", None),
        "resources_dir": str(res),
        "resources": sorted(p.name for p in res.iterdir()) if res.is_dir() else [],
        "samples_dir": str(SAMPLES_DIR),
        "samples": available_samples(),
        "style_dir": str(STYLE_DIR),
        "style_thumbnails": sorted(p.stem for p in Path(STYLE_DIR).glob("*.png")),
    }, indent=2))
    return 0


if __name__ == "__main__":
    # Worker processes started with the "spawn" method (e.g. the neural-subdivision data
    # generation's process pool) re-run this binary; freeze_support() makes them run the worker,
    # not a second app. A no-op outside a frozen app.
    import multiprocessing

    multiprocessing.freeze_support()
    if os.environ.get("STYLIZE3D_BUNDLE_CHECK") == "1":
        sys.exit(_bundle_check())
    from app.__main__ import main

    sys.exit(main())
