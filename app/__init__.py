"""Stylize3D's application layer: the GUI (Qt, VTK in viewport.py only) and the batch CLI."""


def __getattr__(name: str):
    # the version is looked up on first use: importlib.metadata costs ~0.1 s of every command's
    # start-up (``stylize3d info`` must answer in under half a second)
    if name == "__version__":
        from importlib import metadata

        try:
            version = metadata.version("stylize3d")
        except metadata.PackageNotFoundError:  # a source tree that is not installed
            version = "0.1.0"
        globals()["__version__"] = version
        return version
    raise AttributeError(f"module 'app' has no attribute {name!r}")
