"""The model, pure code without SUMO: the episode configuration, the cars and their controllers
(Python controllers and SUMO's car-following models), the attack families and maneuvers, one control
step of a platoon or of many (arrays), and the trace an episode leaves."""
