"""The papers' experiments, our numbers beside theirs (``scripts/reproduce.py``, :mod:`bboxtune.agents.commands.reproduce`).

* :mod:`bboxtune.agents.reproduce.common` — run settings, error measures, markdown tables, verdicts, figure output;
* :mod:`bboxtune.agents.reproduce.shmaliy_cmn` — [Shmaliy-CMN], [Shmaliy-CMN]: Fig. 2 and N_opt(ψ) of UFIR-CMN;
* :mod:`bboxtune.agents.reproduce.mo_fir` — [Mo-FIR], [Mo-FIR]: Table I, KF vs Kwon's FIR;
* :mod:`bboxtune.agents.reproduce.otb` — Car4 and Suv (seeds 000 and 001): OTB ground truth + CMN.

The paper keys are those of ``docs/references.md``. Each experiment module's docstring after its title is the
set-up text of its part of ``reproduction.md``.
"""
