"""Run logs' storage: quotas per user and in all, ended logs compressed, the oldest pruned."""
