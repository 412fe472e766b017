"""Network mode of the processing: marker tables of many stations -> one adjusted network.

Turning observations into coordinates knows nothing of planning.

- :mod:`pipeline.network.association`: which detections of different stations are one marker;
- :mod:`pipeline.network.adjustment`: station poses and marker centres estimated together (the
  observation types, the datum, the least-squares solution and its covariance);
- :mod:`pipeline.network.reliability`: Baarda's reliability and data snooping;
- :mod:`pipeline.network.simulation`: synthetic networks with known truth.
"""
