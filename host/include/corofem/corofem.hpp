// corofem: simplified co-rotational FEM on linear tetrahedra. Umbrella header.
#pragma once

#include <corofem/embed.hpp>
#include <corofem/mesh.hpp>
#include <corofem/scene.hpp>
#include <corofem/simulation.hpp>
#include <corofem/status.hpp>
