"""What a capture says about itself before tracking: the performer's body (subject
estimation), the first pose, the up axis and the units (automatic initialisation), and the
re-initialisation of a track that lost the body. Above ``io`` (it reads captures), below
``trackers`` (the driver re-initialises through it)."""
