"""The reproduction (``pirl reproduce``): its plan, its scheduler, its training jobs and the
sequence that trains, evaluates, flies and reports."""
