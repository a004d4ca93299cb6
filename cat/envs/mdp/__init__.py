"""MDP terms: observations, rewards and terminations as plain functions of the env."""
