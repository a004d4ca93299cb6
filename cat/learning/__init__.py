"""Learning: run configs, rsl_rl runner set-up, rerun logging."""
