"""Visualisation: rerun recordings of rollouts (robot, obstacles, goal, HumanoidPF arrows)."""
