"""The episode layer of :mod:`envs`: an :class:`~bboxtune.envs.episodes.sources.Episode` (measured boxes, truth, the rule's
nominal values) drawn by a source (simulator, OTB replay, tracker output, synthetic video, a mix), the env
arguments (:class:`~bboxtune.envs.episodes.config.EnvConfig`), the action mapping, the observation features and the
scoring of candidate parameters. No Gymnasium: the envs on top (:mod:`bboxtune.envs.tune_env`, :mod:`bboxtune.envs.retune_env`)
turn these into Gym episodes."""
