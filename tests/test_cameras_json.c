/* cameras.json and transforms.json: round trips, the nerfstudio conventions, bad files. */
#include "testutil.h"
#include "gen3d/cameras_json.h"

static void write_text(const char *path, const char *s)
{
    FILE *f = fopen(path, "wb");
    fputs(s, f);
    fclose(f);
}

static void make_list(g3d_camera_list *l)
{
    g3d_rng r;
    g3d_rng_seed(&r, 5, 0);
    g3d_camera_list_create(l, 4);
    for (int i = 0; i < 4; i++) {
        g3d_quat q = g3d_quat_from_axis_angle(g3d_v3(g3d_rng_normal(&r), g3d_rng_normal(&r), g3d_rng_normal(&r)), g3d_rng_float(&r));
        l->cams[i].c2w = g3d_mat4_from_rt(q, g3d_v3(g3d_rng_normal(&r), g3d_rng_normal(&r), g3d_rng_normal(&r)));
        l->cams[i].K = i == 2 ? g3d_intrinsics_make(300, 310, 99.5, 80.25, 200, 160) : g3d_intrinsics_make(500, 500, 255.5, 255.5, 512, 512);
        char name[32];
        snprintf(name, sizeof name, "images/view_%03d.png", i);
        g3d_camera_list_set_name(l, i, name);
        if (i == 3) g3d_camera_list_set_mask(l, i, "masks/view_003.png");
        if (i == 1) g3d_camera_list_set_depth(l, i, "depth/view_001.npy");
    }
}

static void check_same(const g3d_camera_list *a, const g3d_camera_list *b, double tol)
{
    CHECK(a->n == b->n);
    for (int i = 0; i < a->n && i < b->n; i++) {
        CHECK(g3d_mat4_max_abs_diff(a->cams[i].c2w, b->cams[i].c2w) <= tol);
        CHECK_NEAR(a->cams[i].K.fx, b->cams[i].K.fx, tol);
        CHECK_NEAR(a->cams[i].K.cx, b->cams[i].K.cx, tol);
        CHECK_NEAR(a->cams[i].K.cy, b->cams[i].K.cy, tol);
        CHECK(a->cams[i].K.width == b->cams[i].K.width && a->cams[i].K.height == b->cams[i].K.height);
        CHECK(b->names[i] && !strcmp(a->names[i], b->names[i]));
        CHECK((a->mask_paths[i] == NULL) == (b->mask_paths[i] == NULL));
        CHECK((a->depth_paths[i] == NULL) == (b->depth_paths[i] == NULL));
        if (a->depth_paths[i] && b->depth_paths[i]) CHECK(!strcmp(a->depth_paths[i], b->depth_paths[i]));
    }
}

TEST(round_trips)
{
    g3d_camera_list a, b;
    make_list(&a);
    CHECK_OK(g3d_cameras_json_write(test_tmp("cameras.json"), &a));
    CHECK_OK(g3d_camera_list_load(test_tmp("cameras.json"), &b));
    check_same(&a, &b, 1e-12);
    g3d_camera_list_free(&b);
    CHECK_OK(g3d_transforms_json_write(test_tmp("transforms.json"), &a));
    CHECK_OK(g3d_camera_list_load(test_tmp("transforms.json"), &b));
    check_same(&a, &b, 1e-12);
    g3d_camera_list_free(&b);
    g3d_camera_list_free(&a);
}

TEST(nerfstudio_conventions)
{
    /* An identity OpenGL pose looks along -z with y up: in our convention the camera looks
     * along -z of the world with y down, i.e. c2w = diag(1, -1, -1). Pixel centres shift by
     * half a pixel; fl_y defaults to fl_x; per-frame values override the global ones. */
    write_text(test_tmp("ns.json"),
               "{\"camera_model\": \"OPENCV\", \"fl_x\": 400, \"cx\": 320, \"cy\": 240, \"w\": 640, \"h\": 480,"
               " \"k1\": 0, \"frames\": ["
               "{\"file_path\": \"a.png\", \"transform_matrix\": [[1,0,0,1],[0,1,0,2],[0,0,1,3],[0,0,0,1]]},"
               "{\"file_path\": \"b.png\", \"w\": 320, \"h\": 240, \"fl_x\": 200, \"cx\": 160, \"cy\": 120,"
               " \"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]}");
    g3d_camera_list l;
    CHECK_OK(g3d_transforms_json_read(test_tmp("ns.json"), &l));
    if (l.n != 2) return;
    CHECK(l.cams[0].K.fy == 400 && l.cams[0].K.cx == 319.5 && l.cams[0].K.cy == 239.5);
    CHECK(l.cams[1].K.width == 320 && l.cams[1].K.fx == 200 && l.cams[1].K.fy == 200 && l.cams[1].K.cx == 159.5);
    g3d_vec3 fwd = g3d_mat4_dir(l.cams[0].c2w, g3d_v3(0, 0, 1));
    CHECK(fwd.z == -1 && l.cams[0].c2w.m[1][1] == -1 && l.cams[0].c2w.m[0][3] == 1 && l.cams[0].c2w.m[2][3] == 3);
    g3d_camera_list_free(&l);
}

TEST(bad_files)
{
    g3d_camera_list l;
    write_text(test_tmp("bad1.json"), "{\"frames\": [ {\"fx\": 1, ");
    CHECK_FAILS(g3d_cameras_json_read(test_tmp("bad1.json"), &l));
    write_text(test_tmp("bad2.json"), "{\"frames\": [{\"fx\": 500, \"fy\": 500, \"cx\": 1, \"cy\": 1, \"width\": 4, \"height\": 4}]}");
    CHECK_FAILS(g3d_cameras_json_read(test_tmp("bad2.json"), &l)); /* no c2w */
    write_text(test_tmp("bad3.json"), "{\"frames\": [{\"fx\": 500, \"fy\": 500, \"cx\": 1, \"cy\": 1, \"width\": 4, \"height\": 4,"
                                      " \"c2w\": [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]}");
    CHECK_FAILS(g3d_cameras_json_read(test_tmp("bad3.json"), &l)); /* scaled, not rigid */
    write_text(test_tmp("bad4.json"), "{\"fl_x\": 100, \"w\": 64, \"h\": 64, \"cx\": 32, \"cy\": 32, \"frames\": [{\"file_path\": \"x\","
                                      " \"transform_matrix\": [[1,0,0,\"a\"],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]}");
    CHECK_FAILS(g3d_transforms_json_read(test_tmp("bad4.json"), &l));
    write_text(test_tmp("bad5.json"), "{\"camera_model\": \"OPENCV_FISHEYE\", \"frames\": []}");
    CHECK_FAILS(g3d_transforms_json_read(test_tmp("bad5.json"), &l));
    write_text(test_tmp("bad6.json"), "{\"fl_x\": 100, \"k1\": 0.2, \"w\": 64, \"h\": 64, \"frames\": []}");
    CHECK_FAILS(g3d_transforms_json_read(test_tmp("bad6.json"), &l));
    write_text(test_tmp("bad7.json"), "{\"fl_x\": 100, \"w\": 99999, \"h\": 64, \"cx\": 1, \"cy\": 1, \"frames\": [{\"file_path\": \"x\","
                                      " \"transform_matrix\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]}");
    CHECK_FAILS(g3d_transforms_json_read(test_tmp("bad7.json"), &l));
    write_text(test_tmp("bad8.json"), "[1, 2, 3]");
    CHECK_FAILS(g3d_camera_list_load(test_tmp("bad8.json"), &l));
}

int main(void)
{
    RUN(round_trips);
    RUN(nerfstudio_conventions);
    RUN(bad_files);
    return test_summary();
}
