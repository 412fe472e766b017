"""Network mode of the processing: marker tables of many stations -> one adjusted network.

Turning observations into coordinates knows nothing of planning.

- :mod:`pipeline.network.detections`: from ``markers.csv`` tables to the observations;
- :mod:`pipeline.network.association`: which detections of different stations are one marker;
- :mod:`pipeline.network.observations`: the observation types, the datum and nominal poses;
- :mod:`pipeline.network.design`: the linearised observation model (design blocks and weights)
  that the adjustment and the planner's predicted accuracy share;
- :mod:`pipeline.network.adjustment`: station poses and marker centres estimated together (the
  least-squares solution, data snooping and the result);
- :mod:`pipeline.network.settings`: the adjustment's settings (priors, aids, test levels,
  robust estimation, variance components, the body, the covariance's form);
- :mod:`pipeline.network.normals`: its numerical core: linearisation, the sparse normal
  equations, the Gauss-Newton solve and the covariance;
- :mod:`pipeline.network.marginals`: the covariance's marginal blocks (stations, markers,
  observed station-marker pairs) without the full matrix;
- :mod:`pipeline.network.relative`: relative error ellipses between pairs of stations;
- :mod:`pipeline.network.reliability`: Baarda's reliability, the test of each point
  observation (3-D) and data snooping;
- :mod:`pipeline.network.robust`: robust estimation (Huber, IGG-III) by reweighting;
- :mod:`pipeline.network.variance`: variance components of observation groups;
- :mod:`pipeline.network.aids`: odometry between consecutive stations and a heading reference
  with a common boresight bias, as observations of the poses;
- :mod:`pipeline.network.initial`: initial values chained from the reference station;
- :mod:`pipeline.network.body`: the body's curvature: the local vertical's deflection that the
  tilt priors are centred on;
- :mod:`pipeline.network.simulation`: synthetic networks with known truth;
- :mod:`pipeline.network.run`: marker tables in, adjusted network out.
"""
