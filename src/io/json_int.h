/* json_int.h - what the library's JSON writers share. */
#ifndef G3D_JSON_INT_H
#define G3D_JSON_INT_H

#include "gen3d/base.h"

#include <cjson/cJSON.h>

/* Prints root (indented) to `path` atomically and deletes root, also on failure. */
g3d_status g3d_json_save(const char *path, cJSON *root);

#endif /* G3D_JSON_INT_H */
