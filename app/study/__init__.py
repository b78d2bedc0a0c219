"""User-study mode: protocol files, the session log (JSON Lines), replay and summary.

``protocol``, ``log``, ``summary`` and ``replay`` need no Qt (the CLI's ``stylize3d study``
commands use them headless); ``session`` is the Qt side (start dialog, task bar, questionnaire,
locking the app to what a task allows, logging every action through the job runner and the undo
stack).
"""
