"""The parts a scene is composed of, below the scene and the engine.

* ``checks``: the parameter checks and ``SceneError``, shared with the scene;
* ``part``: what every part is (a frozen dataclass of its parameters, their
  flat keys, their checks and their packing for the kernel);
* ``friction``: the friction laws (static threshold, kinetic force, the draw
  at a stop);
* ``loading``: the loadings (how the drive enters the forces and thresholds,
  the next critical drive in closed form);
* ``materials``: the material parameters a pile's posterior infers, one record
  each (name, learned scale, unit, labels, the scene field it sets or gives).

A part holds no scene: its methods take what they need as arguments
(``static_threshold(mu_s, normal, force_tol)``, ``draw_at_stop(seed, sliders,
n_stops)``, ``forces(state, xi, walls, drives)``), and one part asks another
through a named method (``friction.max_stable_incline()``).
"""
