"""The path-space family: ``pt`` (Mitsuba's path / volpath), ``gpt-replay`` and ``gpt``, with their per-path kernels side by side."""
