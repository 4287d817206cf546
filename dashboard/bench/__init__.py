"""The dashboard's benchmark (``heft bench dashboard``)."""
