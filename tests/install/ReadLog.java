// Reads a manip log through manip-lcmtypes.jar and Debian's lcm.jar, the way
// docs/matlab.md does from MATLAB, and prints the same "key value" lines as
// tools/log_summary.cpp (the C++ reader). Codes come from the .lcm consts.
import java.io.EOFException;
import java.io.IOException;

import lcm.logging.Log;
import manip.session_t;
import manip.state_t;
import manip.trial_event_t;

public class ReadLog {
  public static void main(String[] args) throws IOException {
    Log log = new Log(args[0], "r");
    double sampleRateHz = 0;
    int schemaVersion = 0;
    String source = "";
    long states = 0, perturbationStates = 0, onsets = 0, lastCycle = -1;
    try {
      while (true) {
        Log.Event ev = log.readNext();
        if (ev.channel.equals("MANIP_SESSION")) {
          session_t s = new session_t(ev.data);
          sampleRateHz = s.sample_rate_hz;
          schemaVersion = s.schema_version;
          source = s.source;
        } else if (ev.channel.equals("MANIP_STATE")) {
          state_t st = new state_t(ev.data);
          ++states;
          if (st.phase == state_t.PHASE_PERTURBATION) ++perturbationStates;
          lastCycle = st.cycle;
        } else if (ev.channel.equals("MANIP_TRIAL")) {
          trial_event_t t = new trial_event_t(ev.data);
          if (t.kind == trial_event_t.ONSET) ++onsets;
        }
      }
    } catch (EOFException end) {
      // end of log
    }
    log.close();
    // Same number formatting as C++'s default ostream for whole numbers (4000, not 4000.0).
    String rate = sampleRateHz == Math.rint(sampleRateHz) ? Long.toString((long) sampleRateHz) : Double.toString(sampleRateHz);
    System.out.println("sample_rate_hz " + rate);
    System.out.println("schema_version " + schemaVersion);
    System.out.println("source " + source);
    System.out.println("states " + states);
    System.out.println("last_cycle " + lastCycle);
    System.out.println("perturbation_states " + perturbationStates);
    System.out.println("onsets " + onsets);
    System.out.println("PHASE_PERTURBATION " + state_t.PHASE_PERTURBATION);
    System.out.println("MODE_RUNNING " + state_t.MODE_RUNNING);
  }
}
