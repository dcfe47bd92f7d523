/* A ladderd client of your own, in C: Cyclone DDS's C API and the types idlc makes of ladder.idl, nothing of this
 * project's code (docs/server.md, "Your own client"). It reads the scene (what a renderer needs to draw the blocks)
 * and the ladder's states, tips it, prints the flip-flops that follow, then pokes a block that does not exist and
 * prints the refusal.
 *
 *   ladder-c-client [DOMAIN [SIM_ID]]     (defaults: 0, "ladder")
 *
 * Exit status: 0 the tip was accepted and the poke refused, 1 otherwise, 3 no server answered within 10 s. */
#include "dds/dds.h"
#include "ladder.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static const char* g_sim_id = "ladder";
static char g_client_id[64];

static double now_s(void) { return (double)dds_time() * 1e-9; }

static dds_entity_t make(dds_entity_t r, const char* what) {
  if (r < 0) {
    fprintf(stderr, "ladder-c-client: %s: %s\n", what, dds_strretcode(r));
    exit(1);
  }
  return r;
}

/* A reader of `topic`: reliable, keep-last `depth`; transient-local when the server's writer is (State, SceneInfo),
 * so that the latest sample is there at once. */
static dds_entity_t reader(dds_entity_t participant, dds_entity_t topic, int depth, int transient_local) {
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, depth);
  if (transient_local) dds_qset_durability(q, DDS_DURABILITY_TRANSIENT_LOCAL);
  const dds_entity_t r = make(dds_create_reader(participant, topic, q, NULL), "reader");
  dds_delete_qos(q);
  return r;
}

/* The scene of our ladder, printed: its blocks' size (a State gives each block's centre and angle only); 0 if none
 * came within `timeout` seconds. A SceneInfo comes again after a reset, a load or a live setting's change. */
static int print_scene(dds_entity_t scenes, double timeout) {
  for (const double end = now_s() + timeout; now_s() < end; dds_sleepfor(DDS_MSECS(10))) {
    void* samples[16] = {NULL};
    dds_sample_info_t infos[16];
    const int n = dds_take(scenes, samples, infos, 16, 16);
    const ladder_msg_SceneInfo* latest = NULL;
    for (int i = 0; i < n; ++i) {
      const ladder_msg_SceneInfo* s = samples[i];
      if (infos[i].valid_data && strcmp(s->sim_id, g_sim_id) == 0) latest = s;
    }
    if (latest)
      printf("scene '%s': %" PRIu32 " blocks of %.0f x %.0f mm, top block %s, dt %g ms\n", latest->scene_name,
             latest->blocks, latest->length * 1e3, latest->thickness * 1e3, latest->top, latest->dt * 1e3);
    if (n > 0) dds_return_loan(scenes, samples, n);
    if (latest) return 1;
  }
  return 0;
}

/* The latest State of our ladder within `timeout` seconds, printed; 0 if none came. */
static int print_state(dds_entity_t states, double timeout) {
  for (const double end = now_s() + timeout; now_s() < end; dds_sleepfor(DDS_MSECS(10))) {
    void* samples[8] = {NULL};
    dds_sample_info_t infos[8];
    const int n = dds_take(states, samples, infos, 8, 8);
    const ladder_msg_State* latest = NULL;
    for (int i = 0; i < n; ++i) {
      const ladder_msg_State* s = samples[i];
      if (infos[i].valid_data && strcmp(s->sim_id, g_sim_id) == 0 && s->poses._length >= 3) latest = s;
    }
    if (latest) /* poses: x, y, theta of each block in turn [m, m, rad] */
      printf("state: t = %.3f s, %" PRIu32 " blocks, block 0 at (%.4f, %.4f) m turned %.3f rad%s\n",
             latest->sim_time, latest->poses._length / 3, latest->poses._buffer[0], latest->poses._buffer[1],
             latest->poses._buffer[2], latest->paused ? ", paused" : "");
    if (n > 0) dds_return_loan(states, samples, n);
    if (latest) return 1;
  }
  return 0;
}

/* Sends `c` and waits up to 5 s for its answer: 1 accepted, 0 refused, -1 none. Acks go to every client: ours are
 * the ones with our sim id, client id and command id. */
static int call(dds_entity_t commands, dds_entity_t acks, ladder_msg_Command* c, const char* what) {
  static uint64_t next_id = 1;
  strncpy(c->sim_id, g_sim_id, sizeof c->sim_id - 1);
  strncpy(c->client_id, g_client_id, sizeof c->client_id - 1);
  c->command_id = next_id++; /* unique per client: a repeated id gets the first command's answer again */
  make(dds_write(commands, c), "write a command");
  for (const double end = now_s() + 5; now_s() < end; dds_sleepfor(DDS_MSECS(2))) {
    void* samples[16] = {NULL};
    dds_sample_info_t infos[16];
    const int n = dds_take(acks, samples, infos, 16, 16);
    int answer = -1;
    for (int i = 0; i < n; ++i) {
      const ladder_msg_CommandAck* a = samples[i];
      if (!infos[i].valid_data || strcmp(a->sim_id, g_sim_id) != 0 || strcmp(a->client_id, g_client_id) != 0 ||
          a->command_id != c->command_id)
        continue;
      if (a->accepted)
        printf("%s: accepted at t = %.3f s\n", what, a->sim_time);
      else
        printf("%s: refused: %s\n", what, a->reason);
      answer = a->accepted ? 1 : 0;
    }
    if (n > 0) dds_return_loan(acks, samples, n);
    if (answer >= 0) return answer;
  }
  printf("%s: no answer in 5 s\n", what);
  return -1;
}

/* The events of our ladder for `seconds`: the flip-flops printed, the rest counted. */
static void print_events(dds_entity_t events, double seconds) {
  int others = 0;
  for (const double end = now_s() + seconds; now_s() < end; dds_sleepfor(DDS_MSECS(20))) {
    void* samples[64] = {NULL};
    dds_sample_info_t infos[64];
    const int n = dds_take(events, samples, infos, 64, 64);
    for (int i = 0; i < n; ++i) {
      const ladder_msg_Event* e = samples[i];
      if (!infos[i].valid_data || strcmp(e->sim_id, g_sim_id) != 0) continue;
      if (strcmp(e->kind, "flip_flop") == 0)
        printf("event: flip_flop at hinge %" PRId32 ", t = %.3f s\n", e->hinge, e->t);
      else
        ++others;
    }
    if (n > 0) dds_return_loan(events, samples, n);
  }
  printf("events: %d others (impacts, locks, unlocks)\n", others);
}

int main(int argc, char** argv) {
  const dds_domainid_t domain = argc > 1 ? (dds_domainid_t)atoi(argv[1]) : 0;
  if (argc > 2) g_sim_id = argv[2];
  snprintf(g_client_id, sizeof g_client_id, "c-client-%ld", (long)getpid()); /* unique: acks are filtered by it */

  const dds_entity_t participant = make(dds_create_participant(domain, NULL, NULL), "participant");
  /* Topic names are "ladder/<Type>"; every topic is keyed by sim id. */
  const dds_entity_t scene_t =
      make(dds_create_topic(participant, &ladder_msg_SceneInfo_desc, "ladder/SceneInfo", NULL, NULL), "topic");
  const dds_entity_t state_t =
      make(dds_create_topic(participant, &ladder_msg_State_desc, "ladder/State", NULL, NULL), "topic");
  const dds_entity_t command_t =
      make(dds_create_topic(participant, &ladder_msg_Command_desc, "ladder/Command", NULL, NULL), "topic");
  const dds_entity_t ack_t =
      make(dds_create_topic(participant, &ladder_msg_CommandAck_desc, "ladder/CommandAck", NULL, NULL), "topic");
  const dds_entity_t event_t =
      make(dds_create_topic(participant, &ladder_msg_Event_desc, "ladder/Event", NULL, NULL), "topic");

  /* (8 States kept: another publisher under our sim id cannot push the server's out before it is read;
   * docs/server.md, "Why the readers keep more than one") */
  const dds_entity_t scenes = reader(participant, scene_t, 16, 1);
  const dds_entity_t states = reader(participant, state_t, 8, 1);
  const dds_entity_t acks = reader(participant, ack_t, 64, 0);
  const dds_entity_t events = reader(participant, event_t, 64, 0);
  dds_qos_t* q = dds_create_qos(); /* commands: reliable, keep-all */
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(q, DDS_HISTORY_KEEP_ALL, 0);
  const dds_entity_t commands = make(dds_create_writer(participant, command_t, q, NULL), "command writer");
  dds_delete_qos(q);

  /* Connected once a State has come and the server's command reader and ack writer have been found: a command sent
   * before discovery has matched them is lost (DDS drops it, volatile). With several ladders on the domain the
   * counts are any server's; docs/network.md says how to tell ours. */
  int connected = 0;
  if (print_scene(scenes, 10) && print_state(states, 10))
    for (const double end = now_s() + 10; !connected && now_s() < end; dds_sleepfor(DDS_MSECS(10))) {
      dds_publication_matched_status_t to_server;
      dds_subscription_matched_status_t from_server;
      dds_get_publication_matched_status(commands, &to_server);
      dds_get_subscription_matched_status(acks, &from_server);
      connected = to_server.current_count > 0 && from_server.current_count > 0;
    }
  if (!connected) {
    fprintf(stderr,
            "ladder-c-client: no ladderd with sim id '%s' on DDS domain %d in 10 s (is CYCLONEDDS_URI the server's "
            "configuration? docs/network.md)\n",
            g_sim_id, (int)domain);
    dds_delete(participant);
    return 3;
  }

  ladder_msg_Command tip;
  memset(&tip, 0, sizeof tip);
  tip.kind = ladder_msg_TIP;
  const int tipped = call(commands, acks, &tip, "tip");
  if (tipped == 1) print_events(events, 2.5);
  print_state(states, 1);

  ladder_msg_Command poke;
  memset(&poke, 0, sizeof poke);
  poke.kind = ladder_msg_POKE;
  poke.block = 99;
  poke.a = 0.005; /* [N s] sideways */
  const int poked = call(commands, acks, &poke, "poke block 99");

  dds_delete(participant);
  return tipped == 1 && poked == 0 ? 0 : 1;
}
