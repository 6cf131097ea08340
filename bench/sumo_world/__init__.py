"""A third-party world for the attribution bench: Eclipse SUMO (bench only).

Our accuracy figures (bench/accuracy.py) are measured on worlds our synthesiser scripts. This
package takes the world from SUMO instead: independent, widely used, deterministic headless
runs, real road networks from ``netconvert`` (curves, an on-ramp, a junction whose turning
arcs are its internal lanes), its own car-following (Krauss) and lane-change (LC2013) models
producing real lane changes in dense traffic. Nothing in ``ads_rca`` imports it and
``make test`` never runs it; ``python bench/accuracy_sumo.py`` does.

Modules: :mod:`~sumo_world.env` (SUMO's own venv), :mod:`~sumo_world.networks` (plain XML →
``netconvert``), :mod:`~sumo_world.families` (traffic and the partner's manoeuvre),
:mod:`~sumo_world.record` (a headless SUMO run over TraCI at 20 Hz),
:mod:`~sumo_world.scene` (a recording as ``ads_rca.synth.world.Scene``) and
:mod:`~sumo_world.runs` (the synthesiser's fairness rules, log folders).

**How SUMO is driven.** SUMO lives in ``~/.cache/ads_rca/sumo-venv`` (``eclipse-sumo``,
``traci``, ``sumolib`` pinned to one release). Our process appends that venv's site-packages
to ``sys.path`` for the pure-Python ``traci`` and ``sumolib`` and runs ``sumo`` as a child
process over TraCI on a loopback port: the client always matches the server's release, no
compiled SUMO code enters our interpreter (``libsumo`` would, tied to SUMO's build), and a
SUMO crash cannot take the bench down with it. SUMO steps at 50 ms, the log's frame rate.

**What is SUMO's, what is ours.** SUMO's: the road geometry and lane shapes, the ego's path
(the centre lines of its lanes and junction internal lanes, smoothed over 1.5 m), every other
road user's trajectory, including the partner's manoeuvre once it is asked for (its braking,
its LC2013 lane change, its arc through the junction), and the traffic's reactions. Ours: the
ego's stack (``ads_rca.synth.simulate``: camera, detector, tracker, predictor, planner,
controller, with the synthesiser's noise), the injected fault, the choice of partner and the
moment its manoeuvre starts (see :mod:`~sumo_world.families`).

**Closed and open loop.** The ego is a normal SUMO vehicle on its route while recording
(Krauss, no lane changes of its own), so the traffic reacts to it. Our stack's ego then
replaces it and runs in closed loop against SUMO's recorded road users, which are open-loop:
they do not react to what our ego does. To make the world react to *our* ego rather than to
SUMO's, each scene is replayed (up to four SUMO runs): the same commands at the same steps,
SUMO's ego moved (``moveToXY``) along where our fault-free twin drove, the scene rebuilt and
the twin run again until its track settles; where the partner is timed against the ego
(``intersection``, ``merge``, ``crossing``) it is moved so that it reaches the conflict when
our ego, blind to it, would. Faulty runs then replay that last world open-loop: after the
onset, followers and lane changers still react to the fault-free ego's motion, not to the
faulty one's (a faulty ego brakes less, so nothing behind it is hit because of that).

**Lateral dynamics.** The ego steers along SUMO's lane centre line as a vehicle does
(``runs.FOLLOWER``: pure pursuit on a kinematic bicycle with a steering lag,
``ads_rca.synth.steering``): its pose, camera, collision check and recorded pose leave the
plan at a curve's entry by centimetres a step, as a sound path follower's do, and the
commands record the steering it applied. The plan stays the centre line from the ego's pose
(a reference-path planner's), so a curve shows the lag a judge of control must not blame.
"""
