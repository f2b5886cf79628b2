"""The model, pure code without SUMO, in four rooms and the episode that joins them, each layer importing
only those below it:

- `world`: the cars, lanes, traffic, V2V channel, radar and traffic lights;
- `attacks`: the attacker's pedals, lanes and lies;
- `controllers`: the followers' laws, SUMO's models, FMUs, users' classes, and the laws over arrays and in C;
- `config` and `definition`: an episode's configuration (`EpisodeConfig`), and its stored definition;
- `stepping`: one control step of a platoon or of many (arrays), and the trace an episode leaves.
"""
