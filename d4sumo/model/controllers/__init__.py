"""Who drives the followers: the control laws (`control`, `cacc`, `laws/`, one file per added law), SUMO's
own car-following models (`carfollowing`), FMUs (`fmu`), users' classes (`plugins`), the [controller] table
(`table`), a command checked (`commands`), and the same laws over arrays for batches (`arrays`) and compiled
in C (`compiled`, its extension `_followers` built from `_followers.c` and `csrc/`). Imports the world and,
for the lies the compiled followers receive, the attacks."""
