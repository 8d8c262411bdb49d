"""Training with stable-baselines3: the algorithms (:mod:`.algos`) and their YAML hyperparameters
(:mod:`.hyperparams`), run directories (:mod:`.runs`), callbacks and checkpoints (:mod:`.callbacks`,
:mod:`.checkpoints`), the batched ``VecEnv`` (:mod:`.batched`), Ray Tune sweeps (:mod:`.sweep`), and the run files
read back without unpickling (:mod:`.safe_load`, :mod:`.run_files`)."""
