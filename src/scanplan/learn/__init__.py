"""Training the pass agent (SB3 PPO): checkpoints now; the rest of `scanplan.train` later."""
