/*
 * QEMU TCG plugin: counts the guest instructions executed from the first instruction of a
 * "begin" marker function (inclusive) to the first instruction of an "end" marker function
 * (exclusive), for every such interval, and appends each count as a line to a file.
 *
 *   qemu-system-arm ... -plugin tools/qemu-plugin/insn_between.so,begin=0x8001234,end=0x8001240,out=counts.txt
 *
 * Addresses are the markers' entry points with the Thumb bit cleared. The counts include the
 * markers' own call overhead; the firmware measures an empty interval first so the host can
 * subtract it. Interrupts taken inside an interval would be counted too: the firmware runs
 * its intervals with interrupts masked.
 *
 * Debian's QEMU accepts plugins built for API v2 to v4 but ships no header, so the few types
 * and functions used here are declared below (they have kept these signatures since API v1).
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define EXPORT __attribute__((visibility("default")))

typedef uint64_t qemu_plugin_id_t;
struct qemu_plugin_tb;
struct qemu_plugin_insn;
typedef struct qemu_info_t qemu_info_t; /* only passed through */
enum qemu_plugin_cb_flags { QEMU_PLUGIN_CB_NO_REGS, QEMU_PLUGIN_CB_R_REGS, QEMU_PLUGIN_CB_RW_REGS };
typedef void (*qemu_plugin_vcpu_udata_cb_t)(unsigned int vcpu_index, void *userdata);
typedef void (*qemu_plugin_vcpu_tb_trans_cb_t)(qemu_plugin_id_t id, struct qemu_plugin_tb *tb);
typedef void (*qemu_plugin_udata_cb_t)(qemu_plugin_id_t id, void *userdata);

void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id, qemu_plugin_vcpu_tb_trans_cb_t cb);
void qemu_plugin_register_vcpu_insn_exec_cb(struct qemu_plugin_insn *insn, qemu_plugin_vcpu_udata_cb_t cb,
                                            enum qemu_plugin_cb_flags flags, void *userdata);
void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, qemu_plugin_udata_cb_t cb, void *userdata);
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
struct qemu_plugin_insn *qemu_plugin_tb_get_insn(const struct qemu_plugin_tb *tb, size_t idx);
uint64_t qemu_plugin_insn_vaddr(const struct qemu_plugin_insn *insn);

/* The oldest API level whose functions are used here; QEMU 10 accepts 2..4. */
EXPORT int qemu_plugin_version = 2;

static uint64_t begin_addr, end_addr;
static FILE *out;
/* One emulated Cortex-M4: one vCPU, so plain counters suffice. */
static uint64_t count;
static int counting;
static uint64_t intervals;

static void on_insn(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    (void)udata;
    count += (uint64_t)counting;
}

static void on_begin(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    (void)udata;
    counting = 1;
    count = 1; /* the marker's first instruction */
}

static void on_end(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    (void)udata;
    if (!counting) {
        return; /* an end without a begin: nothing to report */
    }
    counting = 0;
    intervals++;
    fprintf(out, "%llu\n", (unsigned long long)count);
    /* The host kills QEMU when it has what it needs: every line must be on disk by then. */
    fflush(out);
}

static void on_translate(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    (void)id;
    size_t n = qemu_plugin_tb_n_insns(tb);
    for (size_t i = 0; i < n; i++) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t pc = qemu_plugin_insn_vaddr(insn);
        qemu_plugin_vcpu_udata_cb_t cb = pc == begin_addr ? on_begin : pc == end_addr ? on_end : on_insn;
        qemu_plugin_register_vcpu_insn_exec_cb(insn, cb, QEMU_PLUGIN_CB_NO_REGS, NULL);
    }
}

static void on_plugin_exit(qemu_plugin_id_t id, void *udata)
{
    (void)id;
    (void)udata;
    if (out != NULL && out != stderr) {
        fclose(out);
    }
}

EXPORT int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info, int argc, char **argv)
{
    (void)info;
    const char *path = NULL;
    for (int i = 0; i < argc; i++) {
        if (strncmp(argv[i], "begin=", 6) == 0) {
            begin_addr = strtoull(argv[i] + 6, NULL, 0) & ~1ULL;
        } else if (strncmp(argv[i], "end=", 4) == 0) {
            end_addr = strtoull(argv[i] + 4, NULL, 0) & ~1ULL;
        } else if (strncmp(argv[i], "out=", 4) == 0) {
            path = argv[i] + 4;
        } else {
            fprintf(stderr, "insn_between: unknown argument %s (begin=, end=, out=)\n", argv[i]);
            return 1;
        }
    }
    if (begin_addr == 0 || end_addr == 0 || begin_addr == end_addr) {
        fprintf(stderr, "insn_between: needs two different marker addresses begin=0x... end=0x...\n");
        return 1;
    }
    out = path != NULL ? fopen(path, "w") : stderr;
    if (out == NULL) {
        fprintf(stderr, "insn_between: cannot open %s\n", path);
        return 1;
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, on_translate);
    qemu_plugin_register_atexit_cb(id, on_plugin_exit, NULL);
    return 0;
}
