"""The command lines of ``scripts/``: one module per script, ``scripts/<name>.py`` = :func:`bboxtune.agents.commands.<name>.main`.

Each module holds the script's argument parser and ``main(argv: list[str] | None = None) -> int`` (``argv`` None:
``sys.argv[1:]``), which returns the exit status or raises ``SystemExit`` (a bad argument: status 2 with one line on
stderr). The user-facing ones are also installed as console scripts (``[project.scripts]`` in ``pyproject.toml``:
``bboxtune-train`` = ``bboxtune.agents.commands.train:main``, …); the benchmarks (``bench_*``) are run from a checkout
only (``bench_train`` runs ``scripts/train.py`` there). ``compare_retune`` is not a script: it is ``compare``'s
FilterRetune-v0 part.
"""
