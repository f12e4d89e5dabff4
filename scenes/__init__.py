# Scene files shipped with shadowcl, installed as the package data shadowcl/scenes.
