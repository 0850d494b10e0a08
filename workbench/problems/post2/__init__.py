"""Parameter and trajectory reconstruction from a problem file, after the POST2 EKF module.

Reference [R3] of docs/ARCHITECTURE.md: "Development of an extended Kalman filter reconstruction
module for NASA's Program to Optimize Simulated Trajectories II (POST2) and its application to the
Huygens probe entry, descent and landing at Titan", M.S. thesis — Ch. 3.1 (EKF logic, Eq. 3.1; any
input an estimated state, any output an observation, observation and weight files vs time, R = W⁻¹,
Joseph form, perturbation Jacobians), Ch. 3.2 (validation cases: Large J2, Tables 3-1/3-2; 6-DOF
ballistic Mars entry, Tables 3-3..3-5), Ch. 5 (the tanh S-curve of bounded parameters, Fig. 5-15).

Modules: ``config`` (schema and the named states/observations/events), ``model`` (the 3/6-DOF
trajectory model: simulator and process model), ``build`` (environment, vehicle, state map),
``truth`` (truth simulator and sensors), ``pipeline`` (stages: observations -> EKF -> RTS),
``scoring``, ``recording``, ``problem`` (the Problem protocol object, kind ``post2``), ``schedules``
(observation weights and system noise vs time or event, Ch. 3.2.3).
Shipped scenarios: ``post2_j2``, ``post2_entry6dof`` and ``post2_mer_quaternion``.
"""
