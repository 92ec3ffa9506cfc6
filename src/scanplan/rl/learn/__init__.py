"""Training the pass agent with SB3 PPO: `config` (TrainConfig), `vec_env` (the training
envs), `teacher` (behaviour cloning), `callbacks` (the paper's quantities into SB3's logger,
checkpoints), `checkpoint` (no pickle), `train` (`train(config) -> TrainResult`)."""
