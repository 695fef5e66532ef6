"""Low-level controllers that turn velocity commands into forces."""
