"""``python -m lidarkit``: same as the ``lidarkit`` console script."""

from lidarkit.cli import main

if __name__ == "__main__":
    main()
