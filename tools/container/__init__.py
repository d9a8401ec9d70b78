"""The course's container image: the engine (Docker or Podman), its base image, the build and its tests
(``make image``, ``make test-image``)."""
