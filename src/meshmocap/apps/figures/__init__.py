"""Pictures for people to look at, written as PNG files.

* :mod:`~meshmocap.apps.figures.evaluation` — plots of evaluation results (and the figure
  helpers the other plots share);
* :mod:`~meshmocap.apps.figures.render` — software rendering of posed meshes and
  skeletons, contact sheets;
* :mod:`~meshmocap.apps.figures.latent` — a GPLVM pose manifold's latent space.
"""
