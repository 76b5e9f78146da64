"""``lidarkit eval``: placeholder until the evaluation layer lands."""
