"""A follower controller of your own that asks for the radar's observation.

A constant time-gap ACC (gap wanted: standstill + time_gap_s x own speed) that knows when its radar
sees nobody ahead (it then cruises to the target speed) and brakes fully when a car ahead is closing in
within panic_gap_m. Run it from this folder (the module is found as Python's -m finds it):

    cd examples/controllers
    d4sumo simulate --controller radar_acc:RadarACC --set radar.range_m=150 --set radar.latency_s=0.2 --start steady
    d4sumo falsify --controller radar_acc:RadarACC --set controller.time_gap_s=1.5 --set radar.gap_noise_m=0.5 \
        --start steady --optimizer ce --db radar_acc.sqlite
"""

from dataclasses import dataclass


@dataclass(frozen=True)
class RadarACCParams:
    time_gap_s: float = 1.2  # [s] the gap wanted beyond the standstill distance, per m/s of own speed
    k_gap: float = 0.25  # [1/s^2] acceleration per metre of gap error
    k_speed: float = 0.8  # [1/s] acceleration per m/s of relative speed
    k_cruise: float = 0.5  # [1/s] acceleration per m/s of speed error on a free road
    panic_gap_m: float = 5.0  # closer than this to a car closing in: full brake


class RadarACC:
    Params = RadarACCParams

    def __init__(self, params, *, setpoint_m, target_speed_mps, vehicle, step_s):
        self.p = params
        self.standstill_m = setpoint_m  # the setpoint is the gap at standstill
        self.target_mps = target_speed_mps
        self.vehicle = vehicle  # its limits: max_accel_mps2, max_decel_mps2

    def observe(self, o):
        """The command in [-1, 1] from what the car knows: ``o.speed_mps`` (its own), and what its radar
        measures: ``o.leader`` (a car ahead within range), ``o.gap_m``, ``o.lead_speed_mps``,
        ``o.relative_speed_mps``."""
        cruise = self.p.k_cruise * (self.target_mps - o.speed_mps)
        if not o.leader:
            return self._pedal(cruise)
        if o.gap_m < self.p.panic_gap_m and o.relative_speed_mps < 0.0:
            return -1.0
        wanted = self.standstill_m + self.p.time_gap_s * o.speed_mps
        follow = self.p.k_gap * (o.gap_m - wanted) + self.p.k_speed * o.relative_speed_mps
        return self._pedal(min(cruise, follow))

    def _pedal(self, accel_mps2):
        limit = self.vehicle.max_accel_mps2 if accel_mps2 >= 0 else self.vehicle.max_decel_mps2
        return max(-1.0, min(1.0, accel_mps2 / limit))
