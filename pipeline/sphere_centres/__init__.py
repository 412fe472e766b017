"""Sphere-centre estimation: a marker's centre from the points of one candidate.

- :mod:`pipeline.sphere_centres.sphere_fit`: the two estimators behind one interface
  (:func:`pipeline.sphere_centres.sphere_fit.fit_sphere`);
- :mod:`pipeline.sphere_centres.line_of_sight_fit`: the noise-aware fits on line-of-sight range
  residuals;
- :mod:`pipeline.sphere_centres.geometric_sphere_fit`: the geometric least-squares fits
  (residuals ``|p - c| - R``) and the constants the estimators share.
"""
