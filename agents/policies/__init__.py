"""Policies that choose a filter's parameters without a trained RL model: the rule, oracles, global search and the
amortised regressor (:mod:`.baselines`), the Sage–Husa adaptive KF (:mod:`.adaptive`), IMM (:mod:`.imm`), and the
gate's file format (:mod:`.gate_file`: where a gated tuner leaves a track alone)."""
