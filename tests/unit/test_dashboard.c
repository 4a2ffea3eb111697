/* test_dashboard.c: the dashboard's pieces that need no network: the event ring
 * (coordinator/render/events.c), the snapshot hub between the event loop and the HTTP threads
 * (coordinator/dashboard/snapshot.c: the event loop never waits for the lock, references keep a snapshot
 * alive), the live preview (coordinator/dashboard/livepreview.c: stamps land where they belong, the PNG
 * decodes), the JSON documents (coordinator/dashboard/api.c) and the token rules (httpauth.c). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>
#include <png.h>

#include "coordinator/dashboard/api.h"
#include "coordinator/render/events.h"
#include "coordinator/dashboard/httpauth.h"
#include "coordinator/dashboard/livepreview.h"
#include "coordinator/dashboard/snapshot.h"
#include "farmproto.h"

static void test_event_ring(void **state)
{
    (void)state;
    tf_events *ev = tf_events_new();
    assert_non_null(ev);
    assert_int_equal(tf_events_last_seq(ev), 0);
    tf_event out[TF_EVENTS_MAX];
    assert_int_equal(tf_events_since(ev, 0, out, TF_EVENTS_MAX), 0);
    for (int i = 1; i <= 3; i++)
        tf_events_add(ev, TF_EV_JOIN, i, -1, "worker %d", i);
    assert_int_equal(tf_events_since(ev, 0, out, TF_EVENTS_MAX), 3);
    assert_int_equal(out[0].seq, 1);
    assert_string_equal(out[2].text, "worker 3");
    assert_int_equal(tf_events_since(ev, 2, out, TF_EVENTS_MAX), 1);
    assert_int_equal(out[0].seq, 3);
    /* overflow: only the newest TF_EVENTS_MAX are kept, oldest first */
    for (int i = 0; i < TF_EVENTS_MAX + 10; i++)
        tf_events_add(ev, TF_EV_REDEAL, -1, i, "task %d", i);
    uint64_t last = tf_events_last_seq(ev);
    assert_int_equal(last, 3 + TF_EVENTS_MAX + 10);
    int n = tf_events_since(ev, 0, out, TF_EVENTS_MAX);
    assert_int_equal(n, TF_EVENTS_MAX);
    assert_int_equal(out[0].seq, last - TF_EVENTS_MAX + 1);
    assert_int_equal(out[n - 1].seq, last);
    for (int i = 1; i < n; i++)
        assert_int_equal(out[i].seq, out[i - 1].seq + 1);
    /* at most max, the newest */
    assert_int_equal(tf_events_since(ev, 0, out, 5), 5);
    assert_int_equal(out[4].seq, last);
    /* long text is cut, not overrun */
    char big[1000];
    memset(big, 'x', sizeof big - 1);
    big[sizeof big - 1] = 0;
    tf_events_add(ev, TF_EV_FAILURE, 1, 1, "%s", big);
    tf_events_since(ev, last, out, 1);
    assert_int_equal(strlen(out[0].text), TF_EVENT_TEXT - 1);
    tf_events_add(NULL, TF_EV_JOIN, 1, 1, "nothing"); /* NULL log: a no-op */
    tf_events_free(ev);
}

static tf_snapshot *snap(uint64_t version)
{
    tf_snapshot *s = calloc(1, sizeof *s);
    s->version = version;
    s->frame = s->frames_total = s->frames_done = s->preview_frame = s->exit_status = -1;
    s->eta_s = -1;
    return s;
}

static void test_hub(void **state)
{
    (void)state;
    tf_dash_hub hub;
    assert_int_equal(tf_hub_init(&hub), 0);
    assert_null(tf_hub_acquire(&hub));
    assert_int_equal(tf_hub_wait(&hub, 0, 10), 0); /* nothing yet: times out */
    tf_snapshot *a = snap(1);
    assert_int_equal(tf_hub_publish(&hub, a, 0), 1);
    tf_snapshot *held = tf_hub_acquire(&hub);
    assert_ptr_equal(held, a);
    assert_int_equal(tf_hub_wait(&hub, 0, 10), 1);
    assert_int_equal(tf_hub_wait(&hub, 1, 10), 0);
    /* a newer snapshot replaces it; the reader's reference keeps the old one alive */
    assert_int_equal(tf_hub_publish(&hub, snap(2), 0), 1);
    assert_int_equal(held->version, 1);
    tf_hub_release(&hub, held); /* freed here (ASan would see a leak or a double free) */
    /* the event loop never waits: with the lock held elsewhere, publishing is refused */
    pthread_mutex_lock(&hub.lock);
    tf_snapshot *c = snap(3);
    assert_int_equal(tf_hub_publish(&hub, c, 0), 0);
    tf_command cmds[TF_HUB_COMMANDS];
    assert_int_equal(tf_hub_take_commands(&hub, cmds, TF_HUB_COMMANDS), 0);
    pthread_mutex_unlock(&hub.lock);
    assert_int_equal(tf_hub_publish(&hub, c, 0), 1);
    /* the command queue is bounded and drains in order */
    for (int i = 0; i < TF_HUB_COMMANDS; i++)
        assert_int_equal(tf_hub_push_command(&hub, (tf_command){TF_CMD_WATERMARK, i}), 0);
    assert_int_equal(tf_hub_push_command(&hub, (tf_command){TF_CMD_STOP, 0}), -1);
    assert_int_equal(tf_hub_take_commands(&hub, cmds, 3), 3);
    assert_int_equal(cmds[2].arg, 2);
    assert_int_equal(tf_hub_take_commands(&hub, cmds, TF_HUB_COMMANDS), TF_HUB_COMMANDS - 3);
    assert_int_equal(cmds[0].arg, 3);
    tf_hub_stop(&hub);
    assert_int_equal(tf_hub_wait(&hub, 99, 1000), -1);
    tf_hub_destroy(&hub);
}

/* The event loop playing its part for test_hub_partial: wait for a reader's request, then
 * publish a full snapshot. */
static void *answer_request(void *arg)
{
    tf_dash_hub *hub = arg;
    for (int i = 0; i < 1000 && tf_hub_watched(hub, 30.0) != 2; i++)
        usleep(1000);
    tf_snapshot *full = snap(11);
    full->partial = 0;
    tf_hub_publish(hub, full, 1);
    return NULL;
}

/* Nobody watching: snapshots are partial and cost no copies.  A reader that finds a partial one
 * asks for a full one and gets it; afterwards it counts as watching. */
static void test_hub_partial(void **state)
{
    (void)state;
    tf_dash_hub hub;
    assert_int_equal(tf_hub_init(&hub), 0);
    assert_int_equal(tf_hub_watched(&hub, 30.0), 0); /* no reader ever */
    tf_snapshot *p = snap(10);
    p->partial = 1;
    assert_int_equal(tf_hub_publish(&hub, p, 0), 1);
    pthread_t loop;
    assert_int_equal(pthread_create(&loop, NULL, answer_request, &hub), 0);
    tf_snapshot *got = tf_hub_acquire(&hub); /* blocks until the full one is out */
    pthread_join(loop, NULL);
    assert_non_null(got);
    assert_int_equal(got->version, 11);
    assert_int_equal(got->partial, 0);
    tf_hub_release(&hub, got);
    assert_int_equal(tf_hub_watched(&hub, 30.0), 1); /* a reader came by: full from now on */
    assert_int_equal(tf_hub_watched(&hub, 0.0), 0);  /* ... but not within no time at all */
    /* with no event loop answering, a reader waits TF_HUB_FULL_WAIT_MS, then takes what is there */
    tf_snapshot *q = snap(12);
    q->partial = 1;
    assert_int_equal(tf_hub_publish(&hub, q, 0), 1);
    got = tf_hub_acquire(&hub);
    assert_int_equal(got->version, 12);
    tf_hub_release(&hub, got);
    assert_int_equal(tf_hub_watched(&hub, 30.0), 2); /* its request is still there, once */
    assert_int_equal(tf_hub_watched(&hub, 30.0), 1);
    tf_hub_destroy(&hub);
}

/* A rectangle's share of the preview grid (a result's `preview` blob), all one sRGB value. */
static uint8_t *share_of(const tf_livepreview *lp, tf_rect r, uint8_t value, size_t *len)
{
    int i0, i1, j0, j1;
    tf_preview_span(&lp->grid, lp->img_w, lp->img_h, r, &i0, &i1, &j0, &j1);
    *len = (size_t)(i1 - i0) * (size_t)(j1 - j0) * 3;
    uint8_t *share = malloc(*len ? *len : 1);
    memset(share, value, *len);
    return share;
}

static void test_live_preview(void **state)
{
    (void)state;
    tf_livepreview *lp = tf_livepreview_new(1024, 512, 256);
    assert_non_null(lp);
    assert_int_equal(lp->w, 256);
    assert_int_equal(lp->h, 128);
    for (int i = 0; i < lp->w * lp->h; i++)
        assert_int_equal(lp->rgba[4 * i + 3], 0); /* nothing rendered yet */
    /* a 64x64 stamp at (128, 64) covers preview pixels [32, 48) x [16, 32) */
    size_t len;
    uint8_t *wire = share_of(lp, (tf_rect){128, 64, 64, 64}, 255, &len);
    assert_int_equal(len, 64 * 64 * 3); /* the grid of a 1024-wide image is the image */
    assert_int_equal(tf_livepreview_put_share(lp, (tf_rect){128, 64, 64, 64}, wire, len - 3), -1);
    assert_int_equal(lp->stamps, 0); /* a blob of the wrong size draws nothing */
    assert_int_equal(tf_livepreview_put_share(lp, (tf_rect){128, 64, 64, 64}, wire, len), 0);
    int opaque = 0;
    for (int y = 0; y < lp->h; y++)
        for (int x = 0; x < lp->w; x++) {
            const uint8_t *p = lp->rgba + 4 * ((size_t)y * lp->w + x);
            int inside = x >= 32 && x < 48 && y >= 16 && y < 32;
            assert_int_equal(p[3] != 0, inside);
            if (inside)
                assert_int_equal(p[0], 255);
            opaque += p[3] != 0;
        }
    assert_int_equal(opaque, 16 * 16);
    assert_int_equal(lp->stamps, 1);
    /* a rectangle outside the image is ignored */
    uint64_t v = lp->version;
    assert_int_equal(tf_livepreview_put_share(lp, (tf_rect){1000, 500, 64, 64}, wire, len), -1);
    assert_int_equal(lp->version, v);
    /* another frame of a sequence starts from an empty image */
    tf_livepreview_frame(lp, 3);
    assert_int_equal(lp->frame, 3);
    assert_int_equal(lp->stamps, 0);
    for (int i = 0; i < lp->w * lp->h; i++)
        assert_int_equal(lp->rgba[4 * i + 3], 0);
    assert_int_equal(tf_livepreview_put_share(lp, (tf_rect){128, 64, 64, 64}, wire, len), 0);
    /* a tiny image is not scaled up; every row lands */
    tf_livepreview *small = tf_livepreview_new(3, 2, 512);
    assert_int_equal(small->w, 3);
    tf_pixel row[3] = {{0.5f, 0, 0, 1, 1, 1}, {0, 0.5f, 0, 1, 1, 1}, {0, 0, 0.5f, 1, 1, 1}};
    tf_livepreview_put_row(small, 1, row);
    assert_int_equal(small->rgba[4 * 3 + 3], 255);
    assert_int_equal(small->rgba[4 * 0 + 3], 0);
    assert_true(small->rgba[4 * 4 + 1] > 100);
    tf_livepreview_free(small);
    /* an image larger than the grid's side: the share is decimated twice, and still lands */
    tf_livepreview *big = tf_livepreview_new(4096, 2048, 256);
    assert_int_equal(big->grid.factor, 4);
    size_t blen;
    uint8_t *bshare = share_of(big, (tf_rect){2048, 1024, 512, 512}, 200, &blen);
    assert_int_equal(blen, 128 * 128 * 3);
    assert_int_equal(tf_livepreview_put_share(big, (tf_rect){2048, 1024, 512, 512}, bshare, blen), 0);
    int bopaque = 0;
    for (int i = 0; i < big->w * big->h; i++)
        bopaque += big->rgba[4 * i + 3] != 0;
    assert_int_equal(bopaque, 32 * 32);
    assert_int_equal(big->rgba[4 * ((size_t)big->w * 80 + 140)], 200);
    free(bshare);
    tf_livepreview_free(big);
    /* the PNG decodes to the same pixels */
    uint8_t *png;
    assert_int_equal(tf_png_encode_rgba(lp->rgba, lp->w, lp->h, &png, &len), 0);
    png_image img;
    memset(&img, 0, sizeof img);
    img.version = PNG_IMAGE_VERSION;
    assert_true(png_image_begin_read_from_memory(&img, png, len));
    assert_int_equal(img.width, 256);
    assert_int_equal(img.height, 128);
    img.format = PNG_FORMAT_RGBA;
    uint8_t *back = malloc(PNG_IMAGE_SIZE(img));
    assert_true(png_image_finish_read(&img, NULL, back, 0, NULL));
    assert_memory_equal(back, lp->rgba, (size_t)lp->w * lp->h * 4);
    free(back);
    free(png);
    free(wire);
    tf_livepreview_free(lp);
}

static void test_api_documents(void **state)
{
    (void)state;
    tf_snapshot *s = snap(7);
    s->state = TF_RUN_RENDERING;
    snprintf(s->scene, sizeof s->scene, "a\xff\xfe.scene"); /* not UTF-8: still a string */
    s->width = 100;
    s->height = 50;
    s->rows_total = 50;
    s->rows_written = 25;
    s->nworkers = 1;
    s->workers = calloc(1, sizeof *s->workers);
    s->workers[0] = (tf_snap_worker){3, "forked", "h\xc3", "c", 2, 1000, 1.0, 0.0, 1.5,
                                     TF_WS_BUSY, 9};
    s->elapsed_s = 2.0;
    json_t *st = tf_api_status(s);
    assert_non_null(st);
    assert_true(json_is_null(json_object_get(st, "frame")));
    assert_true(json_is_null(json_object_get(st, "frames_done")));
    assert_true(json_is_null(json_object_get(st, "eta_s")));
    assert_true(json_real_value(json_object_get(st, "percent")) == 50.0);
    assert_string_equal(json_string_value(json_object_get(st, "scene")), "a??.scene");
    json_decref(st);
    json_t *w = tf_api_workers(s);
    json_t *w0 = json_array_get(json_object_get(w, "workers"), 0);
    assert_int_equal(json_integer_value(json_object_get(w0, "task")), 9);
    assert_string_equal(json_string_value(json_object_get(w0, "state")), "busy");
    assert_true(json_real_value(json_object_get(w0, "busy_fraction")) == 0.5);
    assert_string_equal(json_string_value(json_object_get(w0, "host")), "h?");
    json_decref(w);
    tf_snapshot_free(s);
}

static void test_tokens(void **state)
{
    (void)state;
    uint8_t key[32] = {1, 2, 3};
    char a[65], b[65];
    assert_int_equal(tf_http_token_derive(key, a, sizeof a), 0);
    assert_int_equal(strlen(a), 64);
    key[0] = 9;
    assert_int_equal(tf_http_token_derive(key, b, sizeof b), 0);
    assert_string_not_equal(a, b);
    assert_true(tf_http_token_matches(a, a, strlen(a)));
    assert_false(tf_http_token_matches(a, a, strlen(a) - 1));
    assert_false(tf_http_token_matches(a, b, strlen(b)));
    assert_false(tf_http_token_matches(a, NULL, 0));
    char path[] = "/tmp/tf-token-XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    char tok[TF_HTTP_TOKEN_MAX + 1], err[256];
    assert_true(write(fd, "  a-long-enough-token-1234 \n second line\n", 41) == 41);
    close(fd);
    assert_int_equal(tf_http_token_load(path, tok, sizeof tok, err, sizeof err), 0);
    assert_string_equal(tok, "a-long-enough-token-1234");
    FILE *f = fopen(path, "w");
    fputs("short\n", f);
    fclose(f);
    assert_int_equal(tf_http_token_load(path, tok, sizeof tok, err, sizeof err), -1);
    assert_non_null(strstr(err, path));
    f = fopen(path, "w");
    fputs("has a space in the middle of it\n", f);
    fclose(f);
    assert_int_equal(tf_http_token_load(path, tok, sizeof tok, err, sizeof err), -1);
    unlink(path);
    assert_int_equal(tf_http_token_load(path, tok, sizeof tok, err, sizeof err), -1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_event_ring),   cmocka_unit_test(test_hub),
        cmocka_unit_test(test_hub_partial),
        cmocka_unit_test(test_live_preview), cmocka_unit_test(test_api_documents),
        cmocka_unit_test(test_tokens),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
