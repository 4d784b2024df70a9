"""Named blendshapes from the muscle simulation (issue 27): the activation solve
(:mod:`.solve`, :mod:`.rigsolve`), the ARKit-52 names and mapping (:mod:`.arkit`), ARKit weight
tracks in and out (:mod:`.curves`), and the bake (:mod:`.bake`)."""
