"""What the attacker does: its pedals over time (`pedals`: the knot families and their registry), its lanes
(`maneuvers`: cut-in, cut-out, swerve) and its lies over V2V (`messages`: the message attacks and their
registry). Imports only the world."""
