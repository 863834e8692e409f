// kdspace: search in k-dimensional space with kd-trees. The umbrella header.
#pragma once

#include "kdspace/box.hpp"
#include "kdspace/error.hpp"
#include "kdspace/metric.hpp"
#include "kdspace/points/brute_force.hpp"
#include "kdspace/points/neighbor.hpp"
#include "kdspace/points/params.hpp"
#include "kdspace/points/dynamic_point_tree.hpp"
#include "kdspace/points/point_forest.hpp"
#include "kdspace/points/point_tree.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/collide/contact.hpp"
#include "kdspace/collide/moving_scene.hpp"
#include "kdspace/collide/overlap.hpp"
#include "kdspace/index_pair.hpp"
#include "kdspace/rays/ray.hpp"
#include "kdspace/version.hpp"
