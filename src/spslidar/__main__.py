"""``python -m spslidar``: the ``spslidar`` command (:func:`spslidar.cli.main`)."""

if __name__ == "__main__":  # (imported, as pkgutil.walk_packages does, it runs nothing)
    import sys

    from .cli import main

    sys.exit(main())
