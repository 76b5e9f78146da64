"""Ground-truth generators.

* :mod:`lidarkit.sim.street_camera` — monocular camera in a textured 3D street canyon (ray cast, KITTI intrinsics,
  exact ground truth, nuisances); :mod:`lidarkit.sim.camera` — textured planes by homography.
* :mod:`lidarkit.sim.lidar` — spinning multi-beam LiDAR on Open3D's RaycastingScene (street / open / ground-only
  scenes, per-point times, motion distortion, range noise, ground truth at sweep start, middle or end).

Submodules are imported on demand (Open3D is slow to import): ``from lidarkit.sim.lidar import SimulatedLidarSequence``.
"""
