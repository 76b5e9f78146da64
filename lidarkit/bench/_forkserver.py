"""Preloaded by the process pool's fork server only (never imported elsewhere): see ``lifetime.setup_fork_server``."""

from lidarkit.lifetime import setup_fork_server

setup_fork_server()
