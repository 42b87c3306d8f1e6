"""``python -m imulog``: the same command line as the ``imulog`` script."""

from imulog.cli import main

if __name__ == "__main__":  # pragma: no cover - exercised through a subprocess in tests
    main()
