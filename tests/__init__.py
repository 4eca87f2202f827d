"""The test suite, laid out like the code: ``core/<stage>/`` follows ``hemicube_radiosity/core/``,
``blender/`` the Blender layer (add-on, CLI, packaging, Cycles comparisons), ``support/`` holds
what several tests share (builders, closed forms, the add-on's installation). A package so that
tests import ``tests.support`` by name, never each other."""
