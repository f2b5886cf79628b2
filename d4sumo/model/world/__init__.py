"""The world an episode plays in, as data and pure rules: the cars (vehicle, bodies), the lanes and who is
next to whom, the traffic table, the V2V channel, the radar and what a follower observes (`sensing`), the
traffic lights as a driver obeys them (`signals`), and the road's files (`network`). Imports nothing else of
the model."""
