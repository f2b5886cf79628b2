"""The search: the specification and its robustness (rtamt), the optimisers, campaigns (ask, play,
score, store, tell) and the results database they write."""
