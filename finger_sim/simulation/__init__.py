"""The Simulator's rooms, one job each (`finger_sim.simulate` is their public face):

- `driver`: `Simulator`, fixed-rate stepping on the time grid, breakpoints and substeps;
- `setup`: what a Simulator needs of a scene before its first step, kept per scene;
- `locate`: event location, the crossing predicted inside a step and Illinois regula falsi;
- `crossings`: the non-smooth elements' gap events, bracketed and located inside a step;
- `impact`: a located impact, and the stop's rest mode it may start;
- `results`: the recorded `Trajectory` and the per-state columns.
"""
