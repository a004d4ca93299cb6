"""What a training run leaves behind, read alike by evaluation, training and deployment (issue 29: below eval).

``config``: the run's schema (``TrainCfg``: task, algorithm, runner) and its policy network (``policy_model``);
``config_file``: the ``config.yaml`` beside its checkpoints, read back and merged on resume; ``policy``: the
policy network a checkpoint holds, loaded strictly and safely. No env, runner or training loop is imported here.
"""
