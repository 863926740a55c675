/* Scripted input: SDL events pushed at given frames, so that tests (and demos) drive the viewer as a
 * user would, through the same event handling. A script is a list of items separated by ';' or new
 * lines ('#' starts a comment), each "FRAME ACTION [ARGS]":
 *   F down KEY | F up KEY | F key KEY     key pressed, released, or both (SDL key names: w, F12, -)
 *   F press BUTTON X Y | F release BUTTON X Y   mouse button left, middle or right at pixel (X, Y)
 *   F move X Y                            mouse moved to (X, Y), the buttons held as pressed
 *   F wheel N                             scroll N steps (negative: towards the user)
 *   F resize W H                          resize the window to W x H pixels (as a user dragging its
 *                                         border would: the viewer follows the window's new size)
 *   F quit                                close the window
 * Events of frame F are queued before frame F handles its input (frame 0 is the first). */
#include "viewer.h"

#include <SDL.h>
#include <errno.h>
#include <stdlib.h>
#include <string.h>

typedef enum script_kind {
    SCRIPT_KEY_DOWN,
    SCRIPT_KEY_UP,
    SCRIPT_BUTTON_DOWN,
    SCRIPT_BUTTON_UP,
    SCRIPT_MOVE,
    SCRIPT_WHEEL,
    SCRIPT_RESIZE,
    SCRIPT_QUIT
} script_kind;

typedef struct script_item {
    int frame;
    script_kind kind;
    SDL_Keycode key;
    int button, x, y, wheel;
} script_item;

struct view_script {
    script_item *items;
    size_t count, cap;
    size_t next;        /* items are in frame order; the first not yet pushed */
    int mouse_x, mouse_y;
    uint32_t buttons;   /* SDL_BUTTON masks held */
};

static bool add(view_script *s, script_item it) {
    if (s->count == s->cap) {
        size_t cap = s->cap ? 2 * s->cap : 16;
        script_item *p = realloc(s->items, cap * sizeof *p);
        if (!p) return false;
        s->items = p;
        s->cap = cap;
    }
    s->items[s->count++] = it;
    return true;
}

static bool parse_int(const char *t, long lo, long hi, int *out) {
    char *end;
    errno = 0;
    long v = strtol(t, &end, 10);
    if (end == t || *end || errno || v < lo || v > hi) return false;
    *out = (int)v;
    return true;
}

static int button_of(const char *t) {
    if (strcmp(t, "left") == 0) return SDL_BUTTON_LEFT;
    if (strcmp(t, "middle") == 0) return SDL_BUTTON_MIDDLE;
    if (strcmp(t, "right") == 0) return SDL_BUTTON_RIGHT;
    return 0;
}

/* Parses one item of words w[0..n); false after printing why. */
static bool parse_item(view_script *s, char **w, int n, const char *origin, int item) {
    script_item it = {0};
#define FAIL(...)                                                                 \
    do {                                                                          \
        fprintf(stderr, "raypack view: %s: item %d: ", origin, item);             \
        fprintf(stderr, __VA_ARGS__);                                             \
        fputc('\n', stderr);                                                      \
        return false;                                                             \
    } while (0)
    if (n < 2 || !parse_int(w[0], 0, 100000000, &it.frame))
        FAIL("expected 'FRAME ACTION [ARGS]' with FRAME a frame number >= 0");
    const char *a = w[1];
    if (strcmp(a, "down") == 0 || strcmp(a, "up") == 0 || strcmp(a, "key") == 0) {
        /* SDL's names may have spaces ("Left Shift"): the rest of the item is the name */
        char name[64] = "";
        for (int i = 2; i < n; i++) {
            size_t l = strlen(name);
            snprintf(name + l, sizeof name - l, "%s%s", i > 2 ? " " : "", w[i]);
        }
        if (n < 3) FAIL("'%s' expects a key name", a);
        it.key = SDL_GetKeyFromName(name);
        if (it.key == SDLK_UNKNOWN) FAIL("unknown key '%s' (SDL key names: w, F12, Escape, -, Left Shift)", name);
        it.kind = strcmp(a, "up") == 0 ? SCRIPT_KEY_UP : SCRIPT_KEY_DOWN;
        if (!add(s, it)) FAIL("out of memory");
        if (strcmp(a, "key") == 0) {
            it.kind = SCRIPT_KEY_UP;
            if (!add(s, it)) FAIL("out of memory");
        }
        return true;
    }
    if (strcmp(a, "press") == 0 || strcmp(a, "release") == 0) {
        if (n != 5 || !(it.button = button_of(w[2])) || !parse_int(w[3], -100000, 100000, &it.x) ||
            !parse_int(w[4], -100000, 100000, &it.y))
            FAIL("'%s' expects left, middle or right and a pixel X Y", a);
        it.kind = strcmp(a, "press") == 0 ? SCRIPT_BUTTON_DOWN : SCRIPT_BUTTON_UP;
    } else if (strcmp(a, "move") == 0) {
        if (n != 4 || !parse_int(w[2], -100000, 100000, &it.x) || !parse_int(w[3], -100000, 100000, &it.y))
            FAIL("'move' expects a pixel X Y");
        it.kind = SCRIPT_MOVE;
    } else if (strcmp(a, "wheel") == 0) {
        if (n != 3 || !parse_int(w[2], -1000, 1000, &it.wheel)) FAIL("'wheel' expects a step count");
        it.kind = SCRIPT_WHEEL;
    } else if (strcmp(a, "resize") == 0) {
        if (n != 4 || !parse_int(w[2], 1, 16384, &it.x) || !parse_int(w[3], 1, 16384, &it.y))
            FAIL("'resize' expects a width and a height in pixels, 1..16384");
        it.kind = SCRIPT_RESIZE;
    } else if (strcmp(a, "quit") == 0) {
        if (n != 2) FAIL("'quit' takes no arguments");
        it.kind = SCRIPT_QUIT;
    } else {
        FAIL("unknown action '%s' (expected down, up, key, press, release, move, wheel, resize or quit)", a);
    }
#undef FAIL
    if (!add(s, it)) {
        fprintf(stderr, "raypack view: out of memory\n");
        return false;
    }
    return true;
}

static int by_frame(const void *a, const void *b) {
    const script_item *x = a, *y = b;
    if (x->frame != y->frame) return x->frame < y->frame ? -1 : 1;
    return 0;
}

view_script *view_script_parse(const char *text, const char *origin) {
    view_script *s = calloc(1, sizeof *s);
    char *copy = strdup(text);
    if (!s || !copy) {
        free(s);
        free(copy);
        fprintf(stderr, "raypack view: out of memory\n");
        return NULL;
    }
    bool ok = true;
    int item = 0;
    char *save = NULL;
    for (char *tok = strtok_r(copy, ";\n", &save); tok && ok; tok = strtok_r(NULL, ";\n", &save)) {
        char *hash = strchr(tok, '#');
        if (hash) *hash = '\0';
        char *w[8];
        int n = 0;
        char *save2 = NULL;
        for (char *t = strtok_r(tok, " \t\r", &save2); t; t = strtok_r(NULL, " \t\r", &save2)) {
            if (n == 8) {
                n = 9;
                break;
            }
            w[n++] = t;
        }
        if (n == 0) continue;
        item++;
        if (n > 8) {
            fprintf(stderr, "raypack view: %s: item %d: too many words\n", origin, item);
            ok = false;
            break;
        }
        ok = parse_item(s, w, n, origin, item);
    }
    free(copy);
    if (!ok) {
        view_script_free(s);
        return NULL;
    }
    /* stable by frame: merge sort would do; items of one frame keep their order with an index key */
    for (size_t i = 1; i < s->count; i++) {
        script_item it = s->items[i];
        size_t j = i;
        while (j > 0 && by_frame(&s->items[j - 1], &it) > 0) {
            s->items[j] = s->items[j - 1];
            j--;
        }
        s->items[j] = it;
    }
    return s;
}

int view_script_last_frame(const view_script *s) { return s && s->count ? s->items[s->count - 1].frame : -1; }

void view_script_push(view_script *s, int frame) {
    if (!s) return;
    while (s->next < s->count && s->items[s->next].frame <= frame) {
        const script_item *it = &s->items[s->next++];
        SDL_Event e;
        memset(&e, 0, sizeof e);
        switch (it->kind) {
        case SCRIPT_KEY_DOWN:
        case SCRIPT_KEY_UP:
            e.type = it->kind == SCRIPT_KEY_DOWN ? SDL_KEYDOWN : SDL_KEYUP;
            e.key.state = it->kind == SCRIPT_KEY_DOWN ? SDL_PRESSED : SDL_RELEASED;
            e.key.keysym.sym = it->key;
            e.key.keysym.scancode = SDL_GetScancodeFromKey(it->key);
            break;
        case SCRIPT_BUTTON_DOWN:
        case SCRIPT_BUTTON_UP:
            e.type = it->kind == SCRIPT_BUTTON_DOWN ? SDL_MOUSEBUTTONDOWN : SDL_MOUSEBUTTONUP;
            e.button.button = (uint8_t)it->button;
            e.button.state = it->kind == SCRIPT_BUTTON_DOWN ? SDL_PRESSED : SDL_RELEASED;
            e.button.clicks = 1;
            e.button.x = it->x;
            e.button.y = it->y;
            if (it->kind == SCRIPT_BUTTON_DOWN) s->buttons |= SDL_BUTTON((uint32_t)it->button);
            else s->buttons &= ~SDL_BUTTON((uint32_t)it->button);
            s->mouse_x = it->x;
            s->mouse_y = it->y;
            break;
        case SCRIPT_MOVE:
            e.type = SDL_MOUSEMOTION;
            e.motion.state = s->buttons;
            e.motion.x = it->x;
            e.motion.y = it->y;
            e.motion.xrel = it->x - s->mouse_x;
            e.motion.yrel = it->y - s->mouse_y;
            s->mouse_x = it->x;
            s->mouse_y = it->y;
            break;
        case SCRIPT_WHEEL:
            e.type = SDL_MOUSEWHEEL;
            e.wheel.y = it->wheel;
            e.wheel.direction = SDL_MOUSEWHEEL_NORMAL;
            break;
        case SCRIPT_RESIZE: /* the viewer asks the window system, as a window manager would */
            e.type = SDL_USEREVENT;
            e.user.code = VIEW_EVENT_RESIZE;
            e.user.data1 = (void *)(intptr_t)it->x;
            e.user.data2 = (void *)(intptr_t)it->y;
            break;
        case SCRIPT_QUIT:
            e.type = SDL_QUIT;
            break;
        }
        SDL_PushEvent(&e);
    }
}

void view_script_free(view_script *s) {
    if (!s) return;
    free(s->items);
    free(s);
}
