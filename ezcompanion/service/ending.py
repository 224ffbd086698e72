"""A defined end: the vehicle is left in the mode the user chose when the companion stops.

Without it the vehicle flies on its last setpoint: ArduCopter for its GUIDED timeout (3 s)
and then brakes, PX4 for its offboard-loss timeout (1.0-1.15 s) and then declares a
failsafe, ArduPlane flies its last course for ever (issue 11, measured on SITL). So on every
end (intercepted, missed, aborted, SIGINT/SIGTERM) the companion asks for the mode of
``on_exit`` and waits until the vehicle has acknowledged it and reports it in a heartbeat.

======================  ==================  ==============  ==============  ==============
on_exit                 ArduCopter          ArduPlane       ArduRover       PX4
======================  ==================  ==============  ==============  ==============
``hold``                BRAKE               LOITER          HOLD            AUTO.LOITER
``loiter``              LOITER              LOITER          LOITER          AUTO.LOITER
``rtl``                 RTL                 RTL             RTL             AUTO.RTL
``none``                nothing is sent: the autopilot's own timeout decides
``default``             hold                loiter          hold            hold
======================  ==================  ==============  ==============  ==============

BRAKE, not LOITER, is the copter's hold: ArduCopter's LOITER reads the throttle stick as a
climb rate, so with no RC (or the stick low) it descends; BRAKE holds position and
altitude whatever the sticks say.

The mode is asked for only of a vehicle the companion has sent setpoints to, while it is
still in its guided mode (GUIDED, OFFBOARD), has not disarmed since (nor rebooted), the
link is up and one vehicle alone was heard (never after a ``vehicle_refused``): a vehicle
a pilot (or a failsafe) has already taken elsewhere is left there. The request
(MAV_CMD_DO_SET_MODE) is repeated every ``_RETRY_S`` until it is acknowledged, at most
``_TRIES`` times, and then the vehicle must report the mode in a heartbeat within
``_CONFIRM_S``; a refusal, no answer or another mode is reported (an ``on_exit`` event with
``failed`` true, and a warning on stderr from ``ezcompanion run``), never taken for success.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ezcompanion.records import EventKind
from ezcompanion.service.events import EventLog
from ezcompanion.service.session import VehicleSession
from ezcompanion.service.settings import OnExit
from ezcompanion.wire import (
    Message,
    enum_name,
    is_fixed_wing,
    is_ground_vehicle,
    mavlink,
    mode_parameters,
)

__all__ = ["ExitReport", "end_mode", "exit_choice", "leave_vehicle"]

_RETRY_S = 1.0  # vehicle seconds between requests (an autopilot acks within 0.1 s)
_TRIES = 4
_CONFIRM_S = 3.0  # after the ack, wait this long for a heartbeat showing the mode (1 Hz)

# mode names as pymavlink's tables spell them (PX4's LOITER is AUTO.LOITER, 0x03040000)
_MODES = {
    "ArduCopter": {OnExit.HOLD: "BRAKE", OnExit.LOITER: "LOITER", OnExit.RTL: "RTL"},
    "ArduPlane": {OnExit.HOLD: "LOITER", OnExit.LOITER: "LOITER", OnExit.RTL: "RTL"},
    "ArduRover": {OnExit.HOLD: "HOLD", OnExit.LOITER: "LOITER", OnExit.RTL: "RTL"},
    "PX4": {OnExit.HOLD: "LOITER", OnExit.LOITER: "LOITER", OnExit.RTL: "RTL"},
}
_DEFAULTS = {"ArduCopter": OnExit.HOLD, "ArduPlane": OnExit.LOITER, "ArduRover": OnExit.HOLD,
             "PX4": OnExit.HOLD}  # fmt: skip


@dataclass(frozen=True)
class ExitReport:
    """What became of the vehicle at the end."""

    choice: OnExit  # resolved (never DEFAULT)
    mode: str | None  # the mode asked for (None: nothing asked)
    acknowledged: bool  # COMMAND_ACK accepted
    confirmed: bool  # and a heartbeat reported the mode
    detail: str
    failed: bool  # an end mode was wanted and the vehicle is not known to be in it


def vehicle_class(heartbeat: Message) -> str:
    """ArduCopter, ArduPlane, ArduRover or PX4, from a heartbeat."""
    if heartbeat.autopilot == mavlink.MAV_AUTOPILOT_PX4:
        return "PX4"
    if is_fixed_wing(heartbeat):
        return "ArduPlane"
    if is_ground_vehicle(heartbeat):
        return "ArduRover"
    return "ArduCopter"


def exit_choice(choice: OnExit, heartbeat: Message) -> OnExit:
    """``choice`` with ``default`` resolved for the vehicle that sent ``heartbeat``."""
    return _DEFAULTS[vehicle_class(heartbeat)] if choice is OnExit.DEFAULT else choice


def end_mode(choice: OnExit, heartbeat: Message) -> tuple[str, float, float, float] | None:
    """The mode ``choice`` stands for on this vehicle and the parameters of
    MAV_CMD_DO_SET_MODE that ask for it, from pymavlink's tables
    (:func:`ezcompanion.wire.mode_parameters`); None for ``none``."""
    resolved = exit_choice(choice, heartbeat)
    if resolved is OnExit.NONE:
        return None
    name = _MODES[vehicle_class(heartbeat)][resolved]
    params = mode_parameters(heartbeat, name)
    return None if params is None else (name, *params)


def leave_vehicle(
    choice: OnExit,
    session: VehicleSession,
    events: EventLog,
    *,
    commanded: bool,
    now: Callable[[], float],
    pump: Callable[[float], None],
) -> ExitReport:
    """Ask for the end mode and wait for its ack and a heartbeat showing it.

    ``commanded``: the companion sent the vehicle something to fly (else it is not flying
    the companion's setpoint, and is left alone). ``pump(timeout_s)`` waits up to
    ``timeout_s`` (vehicle time) for frames and feeds them to ``session`` (and keeps the
    companion's heartbeat going)."""
    heartbeat = session.heartbeat
    if heartbeat is None or session.target is None:
        return _report(events, now(), choice, None, detail="no vehicle: nothing to leave")
    resolved = exit_choice(choice, heartbeat)
    if resolved is OnExit.NONE:
        return _report(events, now(), resolved, None, detail="none: nothing sent, the "
                       "autopilot's own timeout decides what the vehicle does")  # fmt: skip
    if session.refused:
        return _report(events, now(), resolved, None, warn=True,
                       detail="several autopilots heard: none is asked for anything")  # fmt: skip
    if not commanded:
        return _report(events, now(), resolved, None,
                       detail="no setpoint was sent to the vehicle: left as it is")
    if not session.connected:
        return _report(events, now(), resolved, None, warn=True,
                       detail="link lost: the end mode cannot be asked for")  # fmt: skip
    if session.heard_disarmed:
        return _report(events, now(), resolved, None,
                       detail="the vehicle is disarmed: left as it is")  # fmt: skip
    if not session.in_guided:
        return _report(events, now(), resolved, None,
                       detail=f"the vehicle is in {session.mode or 'an unknown mode'}, not "
                       "following the companion: left as it is")  # fmt: skip
    mode = end_mode(resolved, heartbeat)
    if mode is None:
        return _report(events, now(), resolved, None, warn=True,
                       detail=f"{vehicle_class(heartbeat)} has no mode for {resolved.value}")
    name, p1, p2, p3 = mode
    command = int(mavlink.MAV_CMD_DO_SET_MODE)
    started = now()
    session.acks.pop(command, None)
    ack: tuple[int, float] | None = None
    for _ in range(_TRIES):
        if session.refused or not session.connected:  # learnt while waiting
            return _report(events, now(), resolved, None, warn=True,
                           detail="the vehicle was lost or refused while asking for the end "
                           "mode")  # fmt: skip
        session.request_mode(p1, p2, p3)
        until = now() + _RETRY_S
        while (ack := session.acks.get(command)) is None and now() < until:
            pump(until - now())
        if ack is not None:
            break
    if ack is None:
        return _report(events, now(), resolved, name, warn=True,
                       detail=f"{name} asked {_TRIES} times, never acknowledged")
    if ack[0] != mavlink.MAV_RESULT_ACCEPTED:
        return _report(events, now(), resolved, name, warn=True,
                       detail=f"{name} refused: {enum_name('MAV_RESULT', ack[0])}")
    until = now() + _CONFIRM_S
    while session.mode != name and now() < until and session.connected:
        pump(until - now())
    if session.mode != name:
        return _report(events, now(), resolved, name, acknowledged=True, warn=True,
                       detail=f"{name} acknowledged but the vehicle reports {session.mode}")
    took = now() - started
    return _report(events, now(), resolved, name, acknowledged=True, confirmed=True,
                   detail=f"vehicle in {name} {took:.2f} s after the end")


def _report(
    events: EventLog,
    time_s: float,
    choice: OnExit,
    mode: str | None,
    *,
    detail: str,
    acknowledged: bool = False,
    confirmed: bool = False,
    warn: bool = False,
) -> ExitReport:
    report = ExitReport(choice, mode, acknowledged, confirmed, detail, failed=warn)
    events.emit(EventKind.ON_EXIT, time_s, f"{choice.value}: {'NOT APPLIED: ' if warn else ''}"
                f"{detail}", on_exit=choice.value, mode=mode, acknowledged=acknowledged,
                confirmed=confirmed, failed=warn)  # fmt: skip
    return report
