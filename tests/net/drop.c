/* A tc classifier that drops DROP_PERCENT % of the packets at random, for the network fault tests
 * (tests/daemon/netfault_test.cpp). This kernel has no tc netem; a BPF program on a clsact qdisc's egress does the
 * same for random loss. Built for the bpf target by Debian's clang (tests/CMakeLists.txt), once per percentage:
 * 20 for a lossy link, 100 for a partition. Loaded with
 *   tc qdisc add dev DEV clsact
 *   tc filter add dev DEV egress bpf da obj drop20.o sec classifier
 * (da: the program's return value is the action; TC_ACT_SHOT drops, TC_ACT_OK passes). */
#include <linux/bpf.h>
#include <linux/pkt_cls.h>

#ifndef DROP_PERCENT
#error "compile with -DDROP_PERCENT=N (0 to 100)"
#endif

/* The helper by its number: no libbpf headers needed. */
static __u32 (*bpf_get_prandom_u32)(void) = (void *)BPF_FUNC_get_prandom_u32;

__attribute__((section("classifier"), used)) int drop(struct __sk_buff *skb) {
  (void)skb;
  return (bpf_get_prandom_u32() % 100) < DROP_PERCENT ? TC_ACT_SHOT : TC_ACT_OK;
}

/* bpf_get_prandom_u32 is available to GPL programs only. */
char _license[] __attribute__((section("license"), used)) = "GPL";
