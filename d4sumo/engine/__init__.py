"""The engine: the one step loop (`loop.play`) and the worlds it plays in, SUMO (`sumo`) and the
SUMO-free ballistic reference (`ballistic`); the roads they play on (`scenarios`)."""
