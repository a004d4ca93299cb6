"""Click-and-Traverse (paper §III-C) in simulation: the deployed robot's data path, a browser view, headless runs.

``lidar`` (simulated Mid-360) -> ``voxel_map`` (log-odds map, field window) -> ``perception`` (HumanoidPF in a
background thread) -> ``kinematics`` (FK of the 13 links) -> ``runtime`` (observation, policy, MuJoCo world);
``viewer`` (viser page), ``headless`` / ``record`` (one goal, rerun), ``cli`` (scripts/click_and_traverse.py),
``bench`` (scripts/bench.py live). See docs/demo.md.
"""
